#version 430
// After sorting: gather each visible splat's draw data into a record in draw order, so the
// vertex shader reads memory sequentially (random reads slow llvmpipe's vertex stage markedly;
// docs/viewer.md). Record of sorted slot i, 4 vec4s:
//   [0] mean2d.xy, 1 / radius, opacity   [1] half-axes a1.xy, a2.xy (pixels)
//   [2] conic a, b, c (Sigma2^-1 = [[a, b], [b, c]]), 0   [3] rgb, 0
// Dispatched per record chunk: sorted slots [u_first, u_first + u_count).
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Order { uint order[]; };
layout(std430, binding = 1) readonly buffer Center { vec4 center[]; };  // mx, my, z, radius
layout(std430, binding = 2) readonly buffer Conic { vec4 conic[]; };    // a, b, c, opacity
layout(std430, binding = 3) readonly buffer Color { vec4 color[]; };
layout(std430, binding = 4) readonly buffer Axes { vec4 axes[]; };
layout(std430, binding = 5) writeonly buffer Records { vec4 rec[]; };

uniform uint u_first;
uniform uint u_count;

void main() {
    uint i = global_index();
    if (i >= u_count) return;
    uint idx = order[u_first + i];
    vec4 c = center[idx];
    if (c.w <= 0.0) {  // culled (only reachable if the visible count was not used)
        rec[RECORD_VEC4S * i] = vec4(0.0);
        return;
    }
    vec4 con = conic[idx];
    rec[RECORD_VEC4S * i] = vec4(c.xy, 1.0 / c.w, con.w);
    rec[RECORD_VEC4S * i + 1u] = axes[idx];
    rec[RECORD_VEC4S * i + 2u] = vec4(con.xyz, 0.0);
    rec[RECORD_VEC4S * i + 3u] = vec4(color[idx].rgb, 0.0);
}
