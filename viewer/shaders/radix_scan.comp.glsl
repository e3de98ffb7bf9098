#version 430
// Radix sort, pass step 2: exclusive prefix sum of the digit-major block histogram, in place, by
// one work group. Entry (digit, block) becomes the first output slot of that block's keys with
// that digit.
layout(local_size_x = 1024) in;

layout(std430, binding = 0) buffer BlockHist { uint block_hist[]; };

uniform uint u_count;  // 16 * n_blocks

shared uint sums[1024];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint per = (u_count + 1023u) / 1024u;
    uint lo = min(t * per, u_count), hi = min(lo + per, u_count);
    uint s = 0u;
    for (uint i = lo; i < hi; ++i) s += block_hist[i];
    sums[t] = s;
    barrier();
    for (uint off = 1u; off < 1024u; off <<= 1) {
        uint v = t >= off ? sums[t - off] : 0u;
        barrier();
        sums[t] += v;
        barrier();
    }
    uint run = sums[t] - s;  // exclusive
    for (uint i = lo; i < hi; ++i) {
        uint v = block_hist[i];
        block_hist[i] = run;
        run += v;
    }
}
