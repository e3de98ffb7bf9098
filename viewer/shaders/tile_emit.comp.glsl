#version 430
// Tile binning, step 2 (after the run totals are scanned): each visible splat writes one
// (tile, slot) entry per tile it touches, at its exclusive prefix position in depth order. A
// stable sort by tile then leaves every tile's entries in depth order: (tile, depth) keys with
// the depth rank implicit in the emission order.
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
uniform sampler2D u_records;  // 4 texels a slot (preprocess.comp.glsl)

#include "tile_common.glsl"

void main() {
    uint run = global_index();
    uint start = run * RUN;
    if (start >= u_count) return;
    uint pos = run_offsets[run];
    for (uint i = 0u; i < RUN; ++i) {
        uint idx = start + i;
        if (idx >= u_count) break;
        if (counts[idx] == 0u) continue;
        uint slot = order[idx];
        Footprint f = footprint(slot);
        for (int ty = f.lo.y; ty <= f.hi.y; ++ty) {
            ivec2 span = row_span(f, ty);
            for (int tx = span.x; tx <= span.y; ++tx) {
                tile_keys[pos] = uint(ty) * u_tiles_x + uint(tx);
                tile_values[pos] = slot;
                pos += 1u;
            }
        }
    }
}
