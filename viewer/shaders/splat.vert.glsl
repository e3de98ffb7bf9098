#version 430
// One quad per Gaussian, in sorted order, spanned by the two half-axes from the preprocess pass:
// either the ellipse where alpha >= 1/255 or the support square (|p - m| <= r per axis) plus half
// a pixel, whichever is smaller; the fragment shader applies the exact support and alpha tests.
// Image row j maps to framebuffer row j.
layout(std430, binding = 0) readonly buffer Order { uint order[]; };
layout(std430, binding = 1) readonly buffer Center { vec4 center[]; };  // mx, my, z, radius
layout(std430, binding = 2) readonly buffer Conic { vec4 conic[]; };    // a, b, c, opacity
layout(std430, binding = 3) readonly buffer Color { vec4 color[]; };
layout(std430, binding = 4) readonly buffer Axes { vec4 axes[]; };      // quad half-axes (2 x vec2)

uniform vec2 u_viewport;

flat out vec3 v_center;  // mx, my, radius
flat out vec4 v_conic;
flat out vec3 v_color;

void main() {
    uint idx = order[gl_InstanceID];
    vec4 c = center[idx];
    if (c.w <= 0.0) {  // culled: a degenerate primitive outside the clip volume
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        return;
    }
    vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)) * 2.0 - 1.0;
    vec4 ax = axes[idx];
    vec2 p = c.xy + corner.x * ax.xy + corner.y * ax.zw;
    gl_Position = vec4(2.0 * p / u_viewport - 1.0, 0.0, 1.0);
    v_center = vec3(c.xy, c.w);
    v_conic = conic[idx];
    v_color = color[idx].rgb;
}
