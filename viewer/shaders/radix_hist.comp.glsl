#version 430
// Radix sort, pass step 1: per block of BLOCK keys, how many have each digit.
// block_hist is digit-major: block_hist[digit * n_blocks + block].
layout(local_size_x = RADIX_THREADS) in;

layout(std430, binding = 0) readonly buffer Keys { uint keys[]; };
layout(std430, binding = 1) writeonly buffer BlockHist { uint block_hist[]; };

uniform uint u_count;
uniform uint u_shift;
uniform uint u_blocks;

#include "radix_common.glsl"

shared uint hist[RADIX_DIGITS];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint block = gl_WorkGroupID.x;
    if (t < RADIX_DIGITS) hist[t] = 0u;
    barrier();
    uint c[RADIX_DIGITS];
    count_digits(block * BLOCK + t * RADIX_ITEMS, c);
    for (uint d = 0u; d < RADIX_DIGITS; ++d) if (c[d] != 0u) atomicAdd(hist[d], c[d]);
    barrier();
    if (t < RADIX_DIGITS) block_hist[t * u_blocks + block] = hist[t];
}
