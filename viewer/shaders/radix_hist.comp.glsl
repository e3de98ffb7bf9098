#version 430
// Radix sort, pass step 1: per block of 4096 keys, how many have each 4-bit digit.
// block_hist is digit-major: block_hist[digit * n_blocks + block].
layout(local_size_x = 256) in;

layout(std430, binding = 0) readonly buffer Keys { uint keys[]; };
layout(std430, binding = 1) writeonly buffer BlockHist { uint block_hist[]; };

uniform uint u_count;
uniform uint u_shift;
uniform uint u_blocks;

#include "radix_common.glsl"

shared uint hist[16];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint block = gl_WorkGroupID.x;
    if (t < 16u) hist[t] = 0u;
    barrier();
    uint c[16];
    count_digits(block * BLOCK + t * ITEMS, c);
    for (uint d = 0u; d < 16u; ++d) if (c[d] != 0u) atomicAdd(hist[d], c[d]);
    barrier();
    if (t < 16u) block_hist[t * u_blocks + block] = hist[t];
}
