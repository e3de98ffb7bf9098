#version 430
// Tile binning, step 1: how many tiles each visible splat touches, in depth order, and each run's
// total (invocation t owns the RUN consecutive sorted splats of run t), plus the grand total and
// the largest run total (tile_emit's dispatches).
// No shared memory or barriers: on llvmpipe a barrier switches between all of a work group's
// SIMD batches, and shared memory is loaded one invocation at a time.
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Order { uint order[]; };  // depth-sorted slots
layout(std430, binding = 1) writeonly buffer Counts { uint counts[]; };
layout(std430, binding = 2) writeonly buffer RunSums { uint run_sums[]; };
layout(std430, binding = 3) buffer Total { uint total; uint longest_run; };

uniform uint u_count;      // visible splats
uniform vec2 u_viewport;
uniform uint u_tiles_x;
uniform sampler2D u_records;  // 4 texels a slot (preprocess.comp.glsl)

#include "tile_common.glsl"

void main() {
    uint run = global_index();
    uint start = run * RUN;
    if (start >= u_count) return;
    uint s = 0u;
    for (uint i = 0u; i < RUN; ++i) {
        uint idx = start + i;
        if (idx >= u_count) break;
        uint n = tiles_touched(footprint(order[idx]));
        counts[idx] = n;
        s += n;
    }
    run_sums[run] = s;
    if (s != 0u) {
        atomicAdd(total, s);
        atomicMax(longest_run, s);
    }
}
