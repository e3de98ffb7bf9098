#version 430
// Tile binning, step 1: how many tiles each visible splat touches, in depth order (thread t of a
// work group owns ITEMS consecutive sorted splats), each block's total, and the grand total.
layout(local_size_x = 256) in;

layout(std430, binding = 0) readonly buffer Order { uint order[]; };  // depth-sorted slots
layout(std430, binding = 1) writeonly buffer Counts { uint counts[]; };
layout(std430, binding = 2) writeonly buffer BlockSums { uint block_sums[]; };
layout(std430, binding = 3) buffer Total { uint total; };

uniform uint u_count;      // visible splats
uniform vec2 u_viewport;
uniform uint u_tiles_x;
uniform sampler2D u_records;  // 4 texels a slot (preprocess.comp.glsl)

#include "tile_common.glsl"

shared uint partial[256];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint start = gl_WorkGroupID.x * BLOCK + t * ITEMS;
    uint s = 0u;
    for (uint i = 0u; i < ITEMS; ++i) {
        uint idx = start + i;
        if (idx >= u_count) break;
        uint n = tiles_touched(footprint(order[idx]));
        counts[idx] = n;
        s += n;
    }
    partial[t] = s;
    barrier();
    for (uint off = 128u; off > 0u; off >>= 1) {
        if (t < off) partial[t] += partial[t + off];
        barrier();
    }
    if (t == 0u) {
        block_sums[gl_WorkGroupID.x] = partial[0];
        atomicAdd(total, partial[0]);
    }
}
