// Radix sort, shared by the histogram and scatter passes (included after their `keys` buffer and
// `u_count`, `u_shift` uniforms): thread t of a work group of 256 owns ITEMS consecutive keys.
const uint ITEMS = 16u;
const uint BLOCK = 256u * ITEMS;

// How many of this thread's keys, from `start`, have each 4-bit digit.
void count_digits(uint start, out uint c[16]) {
    for (uint d = 0u; d < 16u; ++d) c[d] = 0u;
    for (uint i = 0u; i < ITEMS; ++i) {
        uint idx = start + i;
        if (idx < u_count) c[(keys[idx] >> u_shift) & 15u] += 1u;
    }
}
