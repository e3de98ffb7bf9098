#version 430
// Radix sort, pass step 3: stable scatter of keys and values by their 4-bit digit. Thread t of a
// block owns 16 consecutive keys; its rank among the block's keys with the same digit comes from
// an exclusive scan of the (digit, thread) count table in shared memory.
layout(local_size_x = 256) in;

layout(std430, binding = 0) readonly buffer KeysIn { uint keys[]; };
layout(std430, binding = 1) readonly buffer ValuesIn { uint values_in[]; };
layout(std430, binding = 2) writeonly buffer KeysOut { uint keys_out[]; };
layout(std430, binding = 3) writeonly buffer ValuesOut { uint values_out[]; };
layout(std430, binding = 4) readonly buffer BlockHist { uint block_hist[]; };  // scanned

uniform uint u_count;
uniform uint u_shift;
uniform uint u_blocks;

#include "radix_common.glsl"

shared uint table[16 * 256];  // table[digit * 256 + thread]
const uint SCAN_THREADS = 256u;
shared uint sums[SCAN_THREADS];
#include "workgroup_scan.glsl"

void main() {
    uint t = gl_LocalInvocationID.x;
    uint block = gl_WorkGroupID.x;
    uint start = block * BLOCK + t * ITEMS;
    uint c[16];
    count_digits(start, c);
    for (uint d = 0u; d < 16u; ++d) table[d * 256u + t] = c[d];
    barrier();
    // exclusive scan of the 4096-entry table: 16 serial entries per thread, then across threads
    uint s = 0u;
    for (uint i = 0u; i < 16u; ++i) s += table[t * 16u + i];
    uint run = exclusive_prefix(t, s);
    for (uint i = 0u; i < 16u; ++i) {
        uint v = table[t * 16u + i];
        table[t * 16u + i] = run;
        run += v;
    }
    barrier();
    for (uint d = 0u; d < 16u; ++d) {
        c[d] = block_hist[d * u_blocks + block] + table[d * 256u + t] - table[d * 256u];
    }
    for (uint i = 0u; i < ITEMS; ++i) {
        uint idx = start + i;
        if (idx >= u_count) break;
        uint k = keys[idx];
        uint d = (k >> u_shift) & 15u;
        uint dst = c[d];
        c[d] = dst + 1u;
        keys_out[dst] = k;
        values_out[dst] = values_in[idx];
    }
}
