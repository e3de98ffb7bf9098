#version 430
// Radix sort, pass step 2: exclusive prefix sum of the digit-major block histogram, in place, by
// one work group. Entry (digit, block) becomes the first output slot of that block's keys with
// that digit.
layout(local_size_x = RADIX_SCAN_THREADS) in;

layout(std430, binding = 0) buffer BlockHist { uint block_hist[]; };

uniform uint u_count;  // RADIX_DIGITS * n_blocks

const uint SCAN_THREADS = uint(RADIX_SCAN_THREADS);
shared uint sums[SCAN_THREADS];
#include "workgroup_scan.glsl"

void main() {
    uint t = gl_LocalInvocationID.x;
    uint per = (u_count + SCAN_THREADS - 1u) / SCAN_THREADS;
    uint lo = min(t * per, u_count), hi = min(lo + per, u_count);
    uint s = 0u;
    for (uint i = lo; i < hi; ++i) s += block_hist[i];
    uint run = exclusive_prefix(t, s);
    for (uint i = lo; i < hi; ++i) {
        uint v = block_hist[i];
        block_hist[i] = run;
        run += v;
    }
}
