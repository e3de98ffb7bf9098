// Texel k of the compute rasterizer's images, which are 4096 texels wide (viewer/tiles.py
// TEXELS_PER_ROW): llvmpipe fetches texels as vectors but loads storage buffers one invocation at
// a time, so the tile passes read splat data as texels.
const int ROW_SHIFT = 12;

ivec2 texel(int k) {
    return ivec2(k & ((1 << ROW_SHIFT) - 1), k >> ROW_SHIFT);
}
