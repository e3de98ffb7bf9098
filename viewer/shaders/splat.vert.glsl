#version 430
// One splat per sorted record (see splat_records.comp.glsl), drawn either as one triangle per
// splat pulled by gl_VertexID (no instancing: llvmpipe pays per instance and per triangle, so
// fewer, larger primitives are faster there) or as an instanced quad. The shape is spanned by
// the record's half-axes: the ellipse where alpha >= 1/255 or the support square, whichever is
// smaller; the fragment shader applies the exact support and alpha tests.
// Image row j maps to framebuffer row j.
layout(std430, binding = 0) readonly buffer Records { vec4 rec[]; };

uniform vec2 u_viewport;
uniform bool u_triangles;  // true: one pulled triangle per splat; false: instanced quads

// A triangle circumscribing the unit disc (in half-axis units): area 1.3x the quad's.
const vec2 TRIANGLE[3] = vec2[](vec2(0.0, 2.0), vec2(-1.7320508, -1.0), vec2(1.7320508, -1.0));

// The fragment shader evaluates the Gaussian at gl_FragCoord (exact pixel centres) with the
// reference's own formula; interpolating offsets instead loses accuracy on llvmpipe for large,
// clipped primitives.
flat out vec4 v_center;  // mean2d.xy, 1 / radius, opacity
flat out vec3 v_conic;
flat out vec3 v_color;

void main() {
    uint slot = u_triangles ? uint(gl_VertexID) / 3u : uint(gl_InstanceID);
    vec4 r0 = rec[RECORD_VEC4S * slot];
    if (r0.z <= 0.0) {  // culled: a degenerate primitive outside the clip volume
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        return;
    }
    vec2 corner = u_triangles ? TRIANGLE[uint(gl_VertexID) % 3u]
                              : vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)) * 2.0 - 1.0;
    vec4 ax = rec[RECORD_VEC4S * slot + 1u];
    v_center = r0;
    v_conic = rec[RECORD_VEC4S * slot + 2u].xyz;
    v_color = rec[RECORD_VEC4S * slot + 3u].rgb;
    gl_Position = vec4(2.0 * (r0.xy + corner.x * ax.xy + corner.y * ax.zw) / u_viewport - 1.0, 0.0, 1.0);
}
