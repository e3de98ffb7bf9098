// Radix sort, shared by the histogram and scatter passes (included after their `keys` buffer and
// `u_count`, `u_shift` uniforms): thread t of a work group of RADIX_THREADS owns RADIX_ITEMS consecutive keys.
const uint BLOCK = uint(RADIX_THREADS * RADIX_ITEMS);

// How many of this thread's keys, from `start`, have each digit.
void count_digits(uint start, out uint c[RADIX_DIGITS]) {
    for (uint d = 0u; d < RADIX_DIGITS; ++d) c[d] = 0u;
    for (uint i = 0u; i < RADIX_ITEMS; ++i) {
        uint idx = start + i;
        if (idx < u_count) c[(keys[idx] >> u_shift) & (RADIX_DIGITS - 1)] += 1u;
    }
}
