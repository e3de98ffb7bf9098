#version 430
// One splat per Gaussian, in sorted order, drawn either as an instanced quad (4-vertex strip
// per instance) or as one triangle per splat pulled by gl_VertexID (no instancing: llvmpipe
// pays per instance and per triangle, so fewer, larger primitives are faster there).
// The shape is spanned by the two half-axes from the preprocess pass: the ellipse where
// alpha >= 1/255 or the support square, whichever is smaller. The fragment shader applies the
// exact support and alpha tests. Image row j maps to framebuffer row j.
layout(std430, binding = 0) readonly buffer Order { uint order[]; };
layout(std430, binding = 1) readonly buffer Center { vec4 center[]; };  // mx, my, z, radius
layout(std430, binding = 2) readonly buffer Conic { vec4 conic[]; };    // a, b, c, opacity
layout(std430, binding = 3) readonly buffer Color { vec4 color[]; };
layout(std430, binding = 4) readonly buffer Axes { vec4 axes[]; };      // half-axes (2 x vec2)

uniform vec2 u_viewport;
uniform bool u_triangles;  // false: instanced quads; true: one pulled triangle per splat

// A triangle circumscribing the unit disc (in half-axis units): area 1.3x the quad's.
const vec2 TRIANGLE[3] = vec2[](vec2(0.0, 2.0), vec2(-1.7320508, -1.0), vec2(1.7320508, -1.0));

// xy: the offset from the mean whitened by the conic (power = -|xy|^2 / 2); zw: the offset in
// units of the support radius (inside the support iff both |z|, |w| <= 1). Both are affine in
// the pixel position, so interpolating them is exact.
out vec4 v_offset;
flat out vec4 v_color;  // rgb, opacity

void main() {
    uint slot = u_triangles ? uint(gl_VertexID) / 3u : uint(gl_InstanceID);
    uint idx = order[slot];
    vec4 c = center[idx];
    if (c.w <= 0.0) {  // culled: a degenerate primitive outside the clip volume
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        return;
    }
    vec2 corner = u_triangles ? TRIANGLE[uint(gl_VertexID) % 3u]
                              : vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)) * 2.0 - 1.0;
    vec4 ax = axes[idx];
    vec2 d = corner.x * ax.xy + corner.y * ax.zw;
    vec4 con = conic[idx];
    float sa = sqrt(con.x);
    vec2 white = vec2(sa * d.x + con.y / sa * d.y, sqrt(max(con.z - con.y * con.y / con.x, 0.0)) * d.y);
    v_offset = vec4(white, d / c.w);
    v_color = vec4(color[idx].rgb, con.w);
    gl_Position = vec4(2.0 * (c.xy + d) / u_viewport - 1.0, 0.0, 1.0);
}
