// Texel k of the viewer's data images, which are 4096 texels wide (viewer/pipeline.py
// TEXELS_PER_ROW): llvmpipe fetches texels as vectors but loads storage buffers one invocation at
// a time, so the preprocess and the tile passes read their per-splat data as texels.
const int ROW_SHIFT = 12;

ivec2 texel(int k) {
    return ivec2(k & ((1 << ROW_SHIFT) - 1), k >> ROW_SHIFT);
}
