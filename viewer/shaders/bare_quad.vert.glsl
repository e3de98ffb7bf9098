#version 430
// Benchmark baseline: one instanced quad per Gaussian at the splat's position and size, read
// straight from the preprocess buffers in sorted order; no Gaussian, no records.
layout(std430, binding = 0) readonly buffer Order { uint order[]; };
layout(std430, binding = 1) readonly buffer Center { vec4 center[]; };  // mx, my, z, radius
layout(std430, binding = 4) readonly buffer Axes { vec4 axes[]; };

uniform vec2 u_viewport;

void main() {
    uint idx = order[gl_InstanceID];
    vec4 c = center[idx];
    if (c.w <= 0.0) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        return;
    }
    vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)) * 2.0 - 1.0;
    vec4 ax = axes[idx];
    gl_Position = vec4(2.0 * (c.xy + corner.x * ax.xy + corner.y * ax.zw) / u_viewport - 1.0, 0.0, 1.0);
}
