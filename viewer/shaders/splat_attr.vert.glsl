#version 330 core
// The compute-free fallback's splat: the same record as splat.vert (see splat_records.comp.glsl),
// given as per-instance attributes computed by numpy; one triangle (3 vertices) per instance.
layout(location = 0) in vec4 a_r0;  // mean2d.xy, 1 / radius, opacity
layout(location = 1) in vec4 a_r1;  // half-axes a1.xy, a2.xy
layout(location = 2) in vec4 a_r2;  // conic a, b, c, 0
layout(location = 3) in vec4 a_r3;  // rgb, 0

uniform vec2 u_viewport;

const vec2 TRIANGLE[3] = vec2[](vec2(0.0, 2.0), vec2(-1.7320508, -1.0), vec2(1.7320508, -1.0));

flat out vec4 v_center;
flat out vec3 v_conic;
flat out vec3 v_color;

void main() {
    vec2 corner = TRIANGLE[gl_VertexID % 3];
    v_center = a_r0;
    v_conic = a_r2.xyz;
    v_color = a_r3.rgb;
    gl_Position = vec4(2.0 * (a_r0.xy + corner.x * a_r1.xy + corner.y * a_r1.zw) / u_viewport - 1.0, 0.0, 1.0);
}
