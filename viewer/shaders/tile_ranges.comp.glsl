#version 430
// Tile binning, step 3: the range [start, end) of each tile's entries in the tile-sorted keys
// (tiles without entries keep the cleared (0, 0)).
layout(local_size_x = 256) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer TileKeys { uint tile_keys[]; };
layout(std430, binding = 1) buffer Ranges { uvec2 ranges[]; };

uniform uint u_count;  // entries

void main() {
    uint i = global_index();
    if (i >= u_count) return;
    uint k = tile_keys[i];
    if (i == 0u || tile_keys[i - 1u] != k) ranges[k].x = i;
    if (i + 1u == u_count || tile_keys[i + 1u] != k) ranges[k].y = i + 1u;
}
