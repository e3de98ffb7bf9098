#version 430
// Tile binning, step 2 (after the run totals are scanned): each visible splat writes one
// (tile, slot) entry per tile it touches, at its exclusive prefix position in depth order. A
// stable sort by tile then leaves every tile's entries in depth order: (tile, depth) keys with
// the depth rank implicit in the emission order. One dispatch writes the entries of each run from
// its u_skip-th to just before its (u_skip + EMIT_CHUNK)-th: llvmpipe ends an invocation after 65,535
// loop iterations, all its loops together, which a run of 16 splats over thousands of tiles each
// (a close view) exceeds. Splats and rows outside the window are stepped over whole.
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Order { uint order[]; };
layout(std430, binding = 1) readonly buffer Counts { uint counts[]; };
layout(std430, binding = 2) readonly buffer RunOffsets { uint run_offsets[]; };  // scanned run sums
layout(std430, binding = 3) writeonly buffer TileKeys { uint tile_keys[]; };
layout(std430, binding = 4) writeonly buffer TileValues { uint tile_values[]; };

uniform uint u_count;
uniform vec2 u_viewport;
uniform uint u_tiles_x;
uniform uint u_skip;  // entries of each run written by earlier dispatches
uniform sampler2D u_records;  // 4 texels a slot (preprocess.comp.glsl)

#include "tile_common.glsl"

void main() {
    uint run = global_index();
    uint start = run * RUN;
    if (start >= u_count) return;
    uint pos = run_offsets[run];
    uint lo = pos + u_skip, hi = lo + uint(EMIT_CHUNK);  // the positions this dispatch writes
    for (uint i = 0u; i < RUN; ++i) {
        uint idx = start + i;
        if (idx >= u_count || pos >= hi) break;
        uint n = counts[idx];
        if (n == 0u || pos + n <= lo) {
            pos += n;
            continue;
        }
        uint slot = order[idx];
        Footprint f = footprint(slot);
        for (int ty = f.lo.y; ty <= f.hi.y && pos < hi; ++ty) {
            ivec2 span = row_span(f, ty);
            uint len = uint(max(span.y - span.x + 1, 0));
            if (pos + len <= lo) {
                pos += len;
                continue;
            }
            for (int tx = span.x; tx <= span.y && pos < hi; ++tx) {
                if (pos >= lo) {
                    tile_keys[pos] = uint(ty) * u_tiles_x + uint(tx);
                    tile_values[pos] = slot;
                }
                pos += 1u;
            }
        }
    }
}
