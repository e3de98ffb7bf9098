# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The decoder's compiled kernels: what spec sections 4.3, 4.5, 6.1 and 6.2 define, one point at a
time, each releasing the GIL and called on independent blocks of strands from several threads
(:mod:`.parallel`). The arithmetic they share with the writer's (:mod:`._writer`) is in
``_arithmetic.pxi``.

- :func:`map_points`, :func:`map_strands`: the card-to-world mapping (spec 6.1) of many points.
- :func:`decode_strands`: the world-guided prediction of strand points (spec 4.3), decoded.
- :func:`undo_neighbour`: the neighbour prediction across the strands of a card (spec 4.3.1), undone.
- :func:`decode_residuals`: the STRD token stream and extra bits (spec 4.3.2), decoded.
- :func:`segment_frames`: the Gaussians of strand segments (spec 6.2).
- :func:`blend_strands`, :func:`place_points`: interpolated strands' points and card coordinates (spec 4.5).
"""

include "_arithmetic.pxi"


def map_points(const double[:, ::1] frames, int segments, const i64[::1] card, const double[:, ::1] uvd,
               double[:, ::1] out):
    """``out[i]`` = the world point of card coordinates ``uvd[i]`` on ``card[i]``."""
    cdef Py_ssize_t i, n = card.shape[0]
    if frames.shape[1] != 18 or uvd.shape[0] != n or out.shape[0] != n or uvd.shape[1] != 3 or out.shape[1] != 3:
        raise ValueError("map_points: mismatched shapes")
    check_cards(card, frames.shape[0], segments)
    with nogil:
        for i in range(n):
            card_map(&frames[0, 0], segments, card[i], &uvd[i, 0], &out[i, 0], NULL, NULL, NULL)


def map_strands(const double[:, ::1] frames, int segments, const i64[::1] strand_card, const float[:, :, ::1] uvd,
                float[:, :, ::1] out):
    """``out[s, i]`` = the world point of card coordinates ``uvd[s, i]`` on ``strand_card[s]``: float32 in
    and out, mapped in float64 as :func:`map_points` does."""
    cdef Py_ssize_t s, i, n = strand_card.shape[0], p = uvd.shape[1]
    cdef int ch
    cdef double c[3]
    cdef double x[3]
    if (frames.shape[1] != 18 or uvd.shape[0] != n or out.shape[0] != n or out.shape[1] != p or uvd.shape[2] != 3
            or out.shape[2] != 3):
        raise ValueError("map_strands: mismatched shapes")
    check_cards(strand_card, frames.shape[0], segments)
    with nogil:
        for s in range(n):
            for i in range(p):
                for ch in range(3):
                    c[ch] = uvd[s, i, ch]
                card_map(&frames[0, 0], segments, strand_card[s], c, x, NULL, NULL, NULL)
                for ch in range(3):
                    out[s, i, ch] = <float> x[ch]


def decode_strands(plan, layout, const i64[::1] strands_to_code, i64[:, :, ::1] res, double[:, :, ::1] uvd,
                   double[:, :, ::1] rec, double[:, :, ::1] world):
    """Spec 4.3's decoding of the strands ``strands_to_code`` (indices into ``[S]``; every card's
    strands whole, in file order, best card by card so its triangles stay in cache) of ``n`` points on
    the cards of ``layout`` (:class:`.strand_coder.Layout`) under ``plan``
    (:class:`.strand_coder.Recurrence`), from their residuals ``res [S, len(base) + R, 3]`` (base
    samples, then the levels' rows; neighbour prediction undone; with ``plan.row_seg``,
    ``level_guide``'s differences are restored in place), into their card coordinates ``uvd [S, n, 3]``
    (float64, ``y / g``). ``rec`` and ``world`` ``[SCRATCH_STRANDS, n, 3]`` are the scratch of the scaled
    card coordinates and world points of the strand decoding and of those before it that it may
    follow. Returns how many coordinates float32 cannot hold (beyond its range, or NaN: a corrupt
    file)."""
    cdef PlanView plan_view
    cdef CodingView coding_view
    cdef const Plan* pl
    cdef const Coding* co
    cdef Strand st
    cdef Py_ssize_t t, s, j, li, row, i, ch, npts = rec.shape[1], nbase
    cdef Py_ssize_t unrepresentable = 0
    cdef double v
    cdef double pred[3]
    cdef double f[3]
    cdef double* R
    cdef i64* LR
    cdef i64 m
    cdef i64* segref = NULL
    if strands_to_code.shape[0] == 0:
        return 0
    plan_view = PlanView(plan)
    coding_view = CodingView(layout, strands_to_code, rec, world, True)
    coding_view.check_residuals(plan_view, res)
    pl, co, nbase = &plan_view.c, &coding_view.c, plan_view.c.nbase
    if tuple(uvd.shape)[:3] != (res.shape[0], npts, 3):
        raise ValueError("decode_strands: mismatched shapes")
    segref = <i64*> calloc(max(nbase, 1), sizeof(i64))
    if segref == NULL:
        raise MemoryError()
    with nogil:
        for t in range(co.count):
            s = co.order[t]
            start_strand(pl, co, t, &st)
            R = st.R
            for j in range(nbase):
                predict_base(pl, co, &st, j, pred, f)
                for ch in range(3):
                    R[3 * pl.base[j] + ch] = pred[ch] + res[s, j, ch] * f[ch]
                to_world(co.frames, co.segments, st.card, R + 3 * pl.base[j], st.sc, st.W + 3 * pl.base[j])
            if pl.row_seg != NULL:
                segment_references(pl, co, &st, segref)
            LR = &res[s, nbase, 0]
            for li in range(pl.levels):
                for row in range(pl.level_start[li], pl.level_start[li + 1]):
                    i = pl.idx[row]
                    predict_level(pl, co, &st, li, row, pred, f)
                    m = segref[pl.row_seg[row]] if pl.row_seg != NULL else -1
                    if m >= 0:  # stored as the difference from m's (int64, wrapping)
                        for ch in range(3):
                            LR[3 * row + ch] = <i64> (<uint64_t> LR[3 * row + ch] + <uint64_t> res[m, nbase + row, ch])
                    for ch in range(3):
                        R[3 * i + ch] = pred[ch] + LR[3 * row + ch] * f[ch]
                    if li + 1 < pl.levels:  # nothing is predicted from the last level
                        to_world(co.frames, co.segments, st.card, R + 3 * i, st.sc, st.W + 3 * i)
            for i in range(npts):
                for ch in range(3):
                    v = R[3 * i + ch] / st.sc[ch]
                    uvd[s, i, ch] = v
                    if not (fabs(v) <= FLT_MAX):
                        unrepresentable += 1
    free(segref)
    return unrepresentable


def undo_neighbour(i64[:, :, ::1] values, const i64[::1] order, const uint8_t[::1] starts,
                   const uint8_t[:, ::1] mask):
    """Neighbour prediction undone in place (spec 4.3): going through the strands in ``order``, each
    value ``values[s, col, ch]`` with ``mask[col, ch]`` gets the previous strand's added, unless
    ``starts`` marks ``s`` as the first strand of its card. Integers wrap as int64 (a corrupt file
    gives wrong numbers, never a crash)."""
    cdef Py_ssize_t t, s, p, col, ch, n = values.shape[1]
    with nogil:
        for t in range(1, order.shape[0]):
            if starts[t]:
                continue
            s = order[t]
            p = order[t - 1]
            for col in range(n):
                for ch in range(3):
                    if mask[col, ch]:
                        values[s, col, ch] = <i64> (<uint64_t> values[s, col, ch] + <uint64_t> values[p, col, ch])


# --- STRD entropy decoding (spec 4.3.2) ------------------------------------------------------------

cdef enum:  # what decode_residuals returns: 0, or the first fault found
    EMPTY_TABLE = 1
    WORDS_END_EARLY = 2
    STREAM_NOT_ENDED = 3
    EXTRA_BITS_LENGTH = 4
    TOO_LARGE = 5
    NO_MEMORY = 6

FAULTS = {EMPTY_TABLE: "a symbol is coded with an empty frequency table",
          WORDS_END_EARLY: "the rANS word stream ends early",
          STREAM_NOT_ENDED: "the rANS stream does not end where its symbols do",
          EXTRA_BITS_LENGTH: "the extra bits do not have the length the tokens need",
          TOO_LARGE: "a residual is too large to reconstruct exactly in float64",
          NO_MEMORY: "out of memory"}
TRUNCATED = WORDS_END_EARLY


cdef inline int token_bits(int tok) noexcept nogil:
    """The bit class of a token: bitlen of its smallest value."""
    if tok >= DIRECT:
        return tok - DIRECT + 5
    cdef int n = 0
    while tok:
        n += 1
        tok >>= 1
    return n


def decode_residuals(const uint32_t[::1] flat_freq, const uint32_t[::1] flat_start,
                     const uint32_t[::1] states, const uint16_t[::1] words, const uint8_t[::1] extra,
                     const i64[::1] column_array, const uint8_t[::1] first, int lanes,
                     const uint8_t[::1] after_neighbour, int classes, uint8_t[:, :, ::1] sym, i64[:, :, ::1] out):
    """Decode the STRD token stream and extra bits into residuals ``out [S, N, 3]`` (``sym``: scratch
    of the same shape). ``classes`` > 1: a strand marked in ``after_neighbour [S]`` takes the bit class
    of the previous lane's token (its card neighbour's, just decoded) as context too, and the others a
    class of their own. Returns 0, or the first fault found: a key of ``FAULTS``."""
    cdef Py_ssize_t strands = out.shape[0], n = out.shape[1], nwords = words.shape[0]
    cdef Py_ssize_t b, col, lane, s, act, pos = 0, blocks = (strands + lanes - 1) // lanes
    cdef int ch, tok, p, o, nb, t, c
    cdef uint32_t x, slot, f
    cdef const uint32_t* row
    cdef uint64_t z, total_bits = 0, bitpos = 0, i
    cdef uint32_t* xs = <uint32_t*> calloc(lanes, sizeof(uint32_t))
    cdef int* prev = <int*> calloc(3 * lanes, sizeof(int))
    cdef int fault = 0
    if after_neighbour.shape[0] != strands or classes < 1:
        free(xs)
        free(prev)
        raise ValueError("decode_residuals: mismatched neighbour marks or classes")
    if xs == NULL or prev == NULL:
        free(xs)
        free(prev)
        return NO_MEMORY
    with nogil:
        for lane in range(lanes):
            xs[lane] = states[lane]
        for b in range(blocks):
            act = min(lanes, strands - b * lanes)
            for col in range(n):
                if first[col]:
                    for lane in range(3 * lanes):
                        prev[lane] = 0
                for ch in range(3):
                    for lane in range(act):
                        s = b * lanes + lane
                        p = prev[ch * lanes + lane]
                        o = 0
                        if ch >= 1:
                            o = prev[lane]
                        if ch == 2 and prev[lanes + lane] > o:
                            o = prev[lanes + lane]
                        c = 0  # with classes > 1: 0 for a strand with no card neighbour before it, else 1 + ...
                        if classes > 1 and after_neighbour[s]:  # ... lane - 1's token of this step, decoded
                            c = 1 + min(prev[ch * lanes + lane - 1], classes - 2)
                        t = (((column_array[col] * 3 + ch) * CONTEXTS + min(p, PREV_CLASSES - 1) * OTHER_CLASSES
                              + min(o, OTHER_CLASSES - 1)) * classes + c)
                        x = xs[lane]
                        slot = x & ((1 << PROB_BITS) - 1)
                        row = &flat_start[t * ALPHABET]
                        tok = 0  # the token whose range holds slot: small tokens are the likely ones
                        while tok + 1 < ALPHABET and row[tok + 1] <= slot:
                            tok += 1
                        f = flat_freq[t * ALPHABET + tok]
                        if f == 0:  # only an empty table has none
                            fault = EMPTY_TABLE
                            break
                        x = f * (x >> PROB_BITS) + slot - row[tok]
                        if x < LOW:
                            if pos >= nwords:
                                fault = WORDS_END_EARLY
                                break
                            x = (x << 16) | words[pos]
                            pos += 1
                        xs[lane] = x
                        sym[s, col, ch] = tok
                        prev[ch * lanes + lane] = token_bits(tok)
                        if tok >= DIRECT + 49:  # z >= 2^53: beyond what float64 holds exactly
                            fault = TOO_LARGE
                            break
                        if tok >= DIRECT:
                            total_bits += tok - DIRECT + 4
                    if fault:
                        break
                if fault:
                    break
            if fault:
                break
        if not fault:
            if pos != nwords:
                fault = STREAM_NOT_ENDED
            for lane in range(lanes):
                if xs[lane] != LOW:
                    fault = STREAM_NOT_ENDED
        if not fault and (total_bits + 7) // 8 != <uint64_t> extra.shape[0]:
            fault = EXTRA_BITS_LENGTH
        if not fault:  # the extra bits, in the same step order
            for b in range(blocks):
                act = min(lanes, strands - b * lanes)
                for col in range(n):
                    for ch in range(3):
                        for lane in range(act):
                            s = b * lanes + lane
                            tok = sym[s, col, ch]
                            z = tok
                            if tok >= DIRECT:
                                nb = tok - DIRECT + 4
                                z = 1
                                for i in range(<uint64_t> nb):
                                    z = (z << 1) | ((extra[bitpos >> 3] >> (7 - (bitpos & 7))) & 1)
                                    bitpos += 1
                            out[s, col, ch] = <i64> (z >> 1) ^ -<i64> (z & 1)
    free(xs)
    free(prev)
    return fault


# --- Gaussians of strand segments (spec 6.2) -------------------------------------------------------

def segment_frames(const float[:, :, ::1] points, double thickness, float[:, :, ::1] means,
                   float[:, :, ::1] rotations, float[:, :, ::1] scales):
    """Per segment ``p_i -> p_i+1`` of strands ``points [S, P, 3]``: the mean (midpoint), the rotation
    (w, x, y, z) taking +z to the segment direction by the shortest arc (a zero-length segment: the
    identity; a segment along -z: a half turn about x) and the scales ``(d, d, length / 2)``."""
    cdef Py_ssize_t s, i, c, n = points.shape[0], p = points.shape[1]
    cdef double d[3]
    cdef double q[4]
    cdef double length, norm
    if (means.shape[0] != n or rotations.shape[0] != n or scales.shape[0] != n or p < 1
            or means.shape[1] != p - 1 or rotations.shape[1] != p - 1 or scales.shape[1] != p - 1
            or points.shape[2] != 3 or means.shape[2] != 3 or rotations.shape[2] != 4 or scales.shape[2] != 3):
        raise ValueError("segment_frames: mismatched shapes")
    with nogil:
        for s in range(n):
            for i in range(p - 1):
                for c in range(3):
                    d[c] = <double> points[s, i + 1, c] - <double> points[s, i, c]
                    means[s, i, c] = <float> ((<double> points[s, i + 1, c] + <double> points[s, i, c]) / 2)
                length = sqrt(dot3(d, d))
                if length > 0:
                    for c in range(3):
                        d[c] = d[c] / (length if length > 1e-30 else 1e-30)
                else:
                    d[0] = 0.0
                    d[1] = 0.0
                    d[2] = 1.0
                q[0] = 1.0 + d[2]
                q[1] = -d[1]
                q[2] = d[0]
                q[3] = 0.0
                if q[0] < 1e-12:
                    q[0] = 0.0
                    q[1] = 1.0
                    q[2] = 0.0
                norm = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
                for c in range(4):
                    rotations[s, i, c] = <float> (q[c] / norm)
                scales[s, i, 0] = <float> thickness
                scales[s, i, 1] = <float> thickness
                scales[s, i, 2] = <float> (length / 2)


# --- Interpolated strands (spec 4.5) -----------------------------------------------------------------

def blend_strands(const double[:, :, ::1] guides, const i64[:, ::1] parents, const i64[:, ::1] weights,
                  int weight_one, const uint8_t[::1] respaced, double[:, :, ::1] out):
    """Interpolated strands' world points (spec 4.5): per child, the blend ``sum_k weights[k]
    guides[parents[k]] / weight_one`` of its parents' points, resampled at even arc length where
    ``respaced``."""
    cdef Py_ssize_t s, n = parents.shape[0], p = guides.shape[1]
    cdef double* blend
    cdef double* length
    check_blends(guides, parents, weights, weight_one, respaced, n, p)
    if out.shape[0] != n or out.shape[1] != p or out.shape[2] != 3:
        raise ValueError("blend_strands: mismatched shapes")
    blend = <double*> calloc(3 * p, sizeof(double))
    length = <double*> calloc(p, sizeof(double))
    if blend == NULL or length == NULL:
        free(blend)
        free(length)
        raise MemoryError()
    with nogil:
        for s in range(n):
            blend_one(guides, &parents[s, 0], &weights[s, 0], weight_one, respaced[s], blend, length, &out[s, 0, 0])
    free(blend)
    free(length)


def place_points(const double[:, ::1] frames, int segments, const double[:, :, ::1] goal, const i64[::1] card,
                 int steps, int halvings, double per_unit2, float[:, :, ::1] uvd):
    """Card coordinates (float32, into ``uvd``) of strands' world points ``goal [n, P, 3]`` on their cards
    (spec 4.5): each point from the searched Newton steps, starting from the previous point's
    coordinates stepped on by the last step (the root from ``(0, 1/2, 0)``). Returns how many
    coordinates float32 cannot hold (a corrupt file)."""
    cdef Py_ssize_t s, i, c, n = goal.shape[0], p = goal.shape[1]
    cdef double cur[3]
    cdef double prev[3]
    cdef double j[9]
    cdef Py_ssize_t bad = 0
    if (card.shape[0] != n or uvd.shape[0] != n or uvd.shape[1] != p or uvd.shape[2] != 3 or goal.shape[2] != 3
            or frames.shape[1] != 18):
        raise ValueError("place_points: mismatched shapes")
    check_cards(card, frames.shape[0], segments)
    with nogil:
        for s in range(n):
            cur[0], cur[1], cur[2] = 0.0, 0.5, 0.0
            for i in range(p):
                newton_solve(&frames[0, 0], segments, card[s], &goal[s, i, 0], steps, halvings, cur, per_unit2, j)
                for c in range(3):
                    uvd[s, i, c] = <float> cur[c]
                    if not isfinite(uvd[s, i, c]):
                        bad += 1
                    if i > 0:  # the next point starts one more of the last step on
                        cur[c], prev[c] = 2 * cur[c] - prev[c], cur[c]
                    else:
                        prev[c] = cur[c]
    return bad
