// Exclusive prefix sum across a work group (Hillis-Steele in shared memory). Needs, before the
// include, `const uint SCAN_THREADS` (the work-group size) and `shared uint sums[SCAN_THREADS]`.
// Every thread calls it with its own total `s` and gets the sum of the totals of threads 0..t-1.
uint exclusive_prefix(uint t, uint s) {
    sums[t] = s;
    barrier();
    for (uint off = 1u; off < SCAN_THREADS; off <<= 1) {
        uint v = t >= off ? sums[t - off] : 0u;
        barrier();
        sums[t] += v;
        barrier();
    }
    return sums[t] - s;
}
