#version 430
// Once per SH chunk after the decode: copies the chunk's coefficients (3 C floats a Gaussian,
// packed) into an RGBA32F image, each Gaussian starting on a texel (u_stride texels, the tail
// zero), which the preprocess fetches as texels: llvmpipe fetches texels as vectors but loads
// storage buffers one invocation and one component at a time.
layout(local_size_x = LOCAL_SIZE) in;
#include "common.glsl"

layout(std430, binding = 0) readonly buffer Sh { float sh[]; };  // [count * floats]
layout(rgba32f, binding = 0) uniform writeonly image2D u_image;

uniform uint u_count;   // texels: Gaussians x u_stride
uniform uint u_floats;  // 3 C
uniform uint u_stride;  // ceil(3 C / 4)

#include "tile_texel.glsl"

void main() {
    uint k = global_index();
    if (k >= u_count) return;
    uint g = k / u_stride, first = 4u * (k % u_stride);
    vec4 v = vec4(0.0);
    for (uint c = 0u; c < 4u; ++c)
        if (first + c < u_floats) v[c] = sh[g * u_floats + first + c];
    imageStore(u_image, texel(int(k)), v);
}
