#version 430
// Tile binning, step 3: the range [start, end) of each tile's entries in the tile-sorted keys
// (tiles without entries keep the cleared (0, 0)), and the entries' splat slots copied into an
// image, which the blend fetches as texels (vectorised on llvmpipe; storage loads are not).
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer TileKeys { uint tile_keys[]; };
layout(std430, binding = 1) buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 2) readonly buffer TileValues { uint tile_values[]; };
layout(r32ui, binding = 2) uniform writeonly uimage2D u_entries;

uniform uint u_count;  // entries

void main() {
    uint i = global_index();
    if (i >= u_count) return;
    uint k = tile_keys[i];
    if (i == 0u || tile_keys[i - 1u] != k) ranges[k].x = i;
    if (i + 1u == u_count || tile_keys[i + 1u] != k) ranges[k].y = i + 1u;
    int w = imageSize(u_entries).x;
    imageStore(u_entries, ivec2(int(i) % w, int(i) / w), uvec4(tile_values[i]));
}
