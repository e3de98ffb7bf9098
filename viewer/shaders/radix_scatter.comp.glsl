#version 430
// Radix sort, pass step 3: stable scatter of keys and values by their digit. Thread t of a
// block owns RADIX_ITEMS consecutive keys; its rank among the block's keys with the same digit comes from
// an exclusive scan of the (digit, thread) count table in shared memory.
layout(local_size_x = RADIX_THREADS) in;

layout(std430, binding = 0) readonly buffer KeysIn { uint keys[]; };
layout(std430, binding = 1) readonly buffer ValuesIn { uint values_in[]; };
layout(std430, binding = 2) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = 3) writeonly buffer ValuesOut { uint values_out[]; };
layout(std430, binding = 4) readonly buffer BlockHist { uint block_hist[]; };  // scanned

uniform uint u_count;
uniform uint u_shift;
uniform uint u_blocks;

#include "radix_common.glsl"

shared uint table[RADIX_DIGITS * RADIX_THREADS];  // table[digit * RADIX_THREADS + thread]
const uint SCAN_THREADS = uint(RADIX_THREADS);
shared uint sums[SCAN_THREADS];
#include "workgroup_scan.glsl"

void main() {
    uint t = gl_LocalInvocationID.x;
    uint block = gl_WorkGroupID.x;
    uint start = block * BLOCK + t * RADIX_ITEMS;
    uint c[RADIX_DIGITS];
    count_digits(start, c);
    for (uint d = 0u; d < RADIX_DIGITS; ++d) table[d * RADIX_THREADS + t] = c[d];
    barrier();
    // exclusive scan of the table: RADIX_DIGITS serial entries per thread, then across threads
    uint s = 0u;
    for (uint i = 0u; i < RADIX_DIGITS; ++i) s += table[t * RADIX_DIGITS + i];
    uint run = exclusive_prefix(t, s);
    for (uint i = 0u; i < RADIX_DIGITS; ++i) {
        uint v = table[t * RADIX_DIGITS + i];
        table[t * RADIX_DIGITS + i] = run;
        run += v;
    }
    barrier();
    for (uint d = 0u; d < RADIX_DIGITS; ++d) {
        c[d] = block_hist[d * u_blocks + block] + table[d * RADIX_THREADS + t] - table[d * RADIX_THREADS];
    }
    for (uint i = 0u; i < RADIX_ITEMS; ++i) {
        uint idx = start + i;
        if (idx >= u_count) break;
        uint k = keys[idx];
        uint d = (k >> u_shift) & (RADIX_DIGITS - 1);
        uint dst = c[d];
        c[d] = dst + 1u;
        keys_out[dst] = k;
        values_out[dst] = values_in[idx];
    }
}
