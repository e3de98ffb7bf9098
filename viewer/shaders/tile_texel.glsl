// Texel k of the viewer's data images, which are 2^TEXEL_ROW_SHIFT texels wide
// (viewer/shader_constants.py TEXELS_PER_ROW): llvmpipe fetches texels as vectors but loads storage buffers one invocation at
// a time, so the preprocess and the tile passes read their per-splat data as texels.
ivec2 texel(int k) {
    return ivec2(k & ((1 << TEXEL_ROW_SHIFT) - 1), k >> TEXEL_ROW_SHIFT);
}
