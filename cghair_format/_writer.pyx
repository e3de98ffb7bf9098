# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The writer's compiled kernels: its searches, each one point or strand at a time, releasing the GIL.
They predict with the decoder's functions (``_arithmetic.pxi``, shared with :mod:`._decoder`).

- :func:`encode_strands`: the residuals of strand points under spec 4.3's prediction, with the dead zone.
- :func:`level_differences`: ``level_guide``'s refinement residuals as differences (spec 4.3.1).
- :func:`invert_points`: card coordinates of world points, by Newton steps.
- :func:`encode_rans`, :func:`pack_bits`: the STRD tokens rANS-coded and the extra bits packed (spec 4.3.2).
- :func:`chain_order`: the strands' order on each card (spec 7).
- :func:`nearest_roots`, :func:`best_blends`, :func:`fit_blends`, :func:`blend_misses`: the search for
  interpolated strands (spec 4.5, 7).
"""

cimport cython

include "_arithmetic.pxi"


cdef inline double miss2(const double* frames, int m, i64 card, const double* pred, const i64* r,
                         const double* f, const double* sc, const double* target) noexcept nogil:
    """The squared world distance from ``pred + r * f`` (scaled card coordinates; ``f`` the residual's
    step per channel) to ``target``."""
    cdef double p[3]
    cdef double x[3]
    cdef int ch
    for ch in range(3):
        p[ch] = pred[ch] + r[ch] * f[ch]
    to_world(frames, m, card, p, sc, x)
    for ch in range(3):
        x[ch] = x[ch] - target[ch]
    return dot3(x, x)


cdef inline bint fits(const double* frames, int m, i64 card, const double* pred, const i64* r, const double* f,
                      const double* sc, const double* target, double dist2) noexcept nogil:
    """Whether ``pred + r * f`` (scaled card coordinates) maps within ``sqrt(dist2)`` of ``target``."""
    return miss2(frames, m, card, pred, r, f, sc, target) <= dist2


cdef inline void nearest(const double* frames, int m, i64 card, const double* pred, const double* f,
                         const double* sc, const double* point, double dist2, i64* r) noexcept nogil:
    """Where the rounded residual ``r`` (steps ``f``) maps farther than ``sqrt(dist2)`` from ``point``: the
    one of its 26 neighbours that maps nearest instead, if nearer (the writer's dead zone, spec 4.3)."""
    cdef i64 c[3]
    cdef i64 best[3]
    cdef double d, best_d = miss2(frames, m, card, pred, r, f, sc, point)
    cdef int ch, du, dv, dd
    if best_d <= dist2:
        return
    for ch in range(3):
        best[ch] = r[ch]
    for du in range(-1, 2):
        for dv in range(-1, 2):
            for dd in range(-1, 2):
                c[0] = r[0] + du
                c[1] = r[1] + dv
                c[2] = r[2] + dd
                d = miss2(frames, m, card, pred, c, f, sc, point)
                if d < best_d:
                    best_d = d
                    for ch in range(3):
                        best[ch] = c[ch]
    for ch in range(3):
        r[ch] = best[ch]


cdef i64 ZERO[3]  # a zero residual, as C's static storage starts


@cython.final  # (its methods called directly, inlined, in the writer's loop)
cdef class ZoneView:
    """The writer's dead zone (:class:`.strand_coder.ZoneArrays`, or None: none) for strands of ``shape
    [S, n, 3]``, checked and held for one :func:`encode_strands` call, with where it stands in the
    strand being coded."""
    cdef const double[:, :, ::1] points
    cdef const uint8_t[:, ::1] free
    cdef bint on, neighbour
    cdef double dist2
    cdef const double* Z  # the strand's points (world), ...
    cdef const uint8_t* FREE  # ... its samples that take any residual (NULL: none) ...
    cdef const i64* NB  # ... and the residuals of the strand a residual may copy (NULL: none)

    def __cinit__(self, zone, tuple shape):
        self.on = zone is not None and zone.points is not None and zone.distance >= 0
        if not self.on:
            return
        self.points, self.free, self.neighbour = zone.points, zone.free, zone.neighbour
        self.dist2 = zone.distance * zone.distance
        if (tuple(self.points.shape)[:3] != shape
                or (self.free is not None and (self.free.shape[0] != shape[0] or self.free.shape[1] != shape[1]))):
            raise ValueError("encode_strands: mismatched shapes")

    cdef inline void start(self, const Coding* co, Py_ssize_t s, const i64* neighbour_res) noexcept nogil:
        """At the start of strand ``s``, with ``neighbour_res`` its card neighbour's residuals (NULL: none)."""
        self.NB = NULL
        if not self.on:
            return
        self.Z = &self.points[s, 0, 0]
        if self.neighbour:
            self.NB = neighbour_res
        self.FREE = NULL
        if self.free is not None:
            self.FREE = &self.free[s, 0]

    cdef inline void settle(self, const Coding* co, const Strand* st, const double* pred, const double* f,
                            i64 sample, i64* r, Py_ssize_t column, bint refinement) noexcept nogil:
        """The residual ``r`` of ``sample`` (``column``: its place in a strand's residuals) under the
        dead zone: the nearest of its 26 neighbours where it maps farther; ``NB``'s where that maps
        within the zone, else for a ``refinement`` sample zero where that does; anything (``NB``'s,
        else zero) for a free sample."""
        cdef const double* z = self.Z + 3 * sample
        cdef int ch
        if not self.on:
            return
        nearest(co.frames, co.segments, st.card, pred, f, st.sc, z, self.dist2, r)
        if self.NB != NULL and fits(co.frames, co.segments, st.card, pred, self.NB + column, f, st.sc, z,
                                    self.dist2):
            for ch in range(3):  # the neighbour's residual will do: its difference is zero
                r[ch] = self.NB[column + ch]
        elif refinement and fits(co.frames, co.segments, st.card, pred, ZERO, f, st.sc, z, self.dist2):
            r[0] = 0
            r[1] = 0
            r[2] = 0
        if self.FREE != NULL and self.FREE[sample]:
            for ch in range(3):
                r[ch] = self.NB[column + ch] if self.NB != NULL else 0


def invert_points(const double[:, ::1] frames, int segments, const i64[::1] card, double[:, ::1] uvd,
                  const double[:, ::1] goal, int steps, double[::1] miss_out):
    """Card coordinates of world points, in place: from ``uvd[i]``, up to ``steps`` Newton steps on
    ``map(card[i], uvd) = goal[i]``, each kept only where it brings the point nearer (no halving);
    ``miss_out[i]`` gets the distance left."""
    cdef Py_ssize_t i, n = card.shape[0]
    cdef int ch
    cdef double c[3]
    cdef double j[9]
    if (frames.shape[1] != 18 or uvd.shape[0] != n or goal.shape[0] != n or uvd.shape[1] != 3
            or goal.shape[1] != 3 or miss_out.shape[0] != n):
        raise ValueError("invert_points: mismatched shapes")
    check_cards(card, frames.shape[0], segments)
    with nogil:
        for i in range(n):
            for ch in range(3):
                c[ch] = uvd[i, ch]
            miss_out[i] = sqrt(newton_solve(&frames[0, 0], segments, card[i], &goal[i, 0], steps, 0, c, 0.0, j))
            for ch in range(3):
                uvd[i, ch] = c[ch]


def encode_strands(plan, layout, const i64[::1] strands_to_code, const double[:, :, ::1] y, state, zone=None,
                   Py_ssize_t first=0):
    """The writer's side of spec 4.3 for the strands ``strands_to_code`` (as :func:`._decoder.decode_strands`
    takes them, with the same ``plan`` and ``layout``): into ``state`` (:class:`.strand_coder.Coded`),
    the residuals ``residuals [S, len(base) + R, 3]`` of the scaled card coordinates ``y [S, n, 3]``,
    and the reconstruction a decoder will get, scaled (``rec [S, n, 3]``) and in world space
    (``world``). Each residual is the rounded difference from the decoder's prediction
    (:func:`predict_base`, :func:`predict_level`), then, with a dead zone (``zone``,
    :class:`.strand_coder.ZoneArrays` with ``distance >= 0``: within it of its ``points``), the nearest
    of its 26 neighbours where it maps farther, a refinement residual zero where the prediction alone
    will do and, with ``zone.neighbour``, first the card neighbour's residual (or the level
    reference's; its stored difference is then zero). Where ``zone.free [S, n]`` is set (placeholders
    a decoder drops and no kept sample is predicted from, spec 3) any residual will do: the card
    neighbour's with ``zone.neighbour``, else zero.

    With ``plan.row_seg`` (``level_guide``) each base segment of a strand with a card neighbour has a
    reference strand (:func:`segment_references`), written to ``state.level_ref [S, len(base) - 1]``
    (-1: none; the caller takes the differences). The strands before position ``first`` are coded
    already (their ``rec``, ``world`` and ``residuals`` as the writer left them, before the level
    differences): the ones after follow them as if coded in one run."""
    cdef PlanView plan_view
    cdef CodingView coding_view
    cdef ZoneView dz
    cdef const Plan* pl
    cdef const Coding* co
    cdef Strand st
    cdef i64[:, :, ::1] res
    cdef i64[:, ::1] level_ref
    cdef Py_ssize_t t, s, j, li, row, i, ch, nbase
    cdef bint dead_zone
    cdef double pred[3]
    cdef double f[3]
    cdef const double* Y
    cdef i64* BR
    cdef i64* LR
    cdef i64 c, m
    cdef i64* segref = NULL
    if strands_to_code.shape[0] == 0:
        return 0
    plan_view = PlanView(plan)
    coding_view = CodingView(layout, strands_to_code, state.rec, state.world, False)
    res, level_ref = state.residuals, state.level_ref
    coding_view.check_residuals(plan_view, res)
    pl, co, nbase = &plan_view.c, &coding_view.c, plan_view.c.nbase
    shape = (res.shape[0], co.points, 3)
    dz = ZoneView(zone, shape)
    dead_zone = dz.on
    if (tuple(y.shape)[:3] != shape
            or (pl.row_seg != NULL and level_ref is not None
                and (level_ref.shape[0] != shape[0] or level_ref.shape[1] != max(nbase - 1, 0)))):
        raise ValueError("encode_strands: mismatched shapes")
    if first < 0 or first > co.count:
        raise ValueError("encode_strands: first must lie in [0, strands]")
    segref = <i64*> calloc(max(nbase, 1), sizeof(i64))
    if segref == NULL:
        raise MemoryError()
    with nogil:
        for t in range(first, co.count):
            s = co.order[t]
            start_strand(pl, co, t, &st)
            BR = &res[s, 0, 0]
            LR = BR + 3 * nbase
            Y = &y[s, 0, 0]
            dz.start(co, s, &res[co.order[t - 1], 0, 0] if st.WN != NULL else NULL)
            for j in range(nbase):
                c = pl.base[j]
                predict_base(pl, co, &st, j, pred, f)
                for ch in range(3):
                    BR[3 * j + ch] = <i64> rint((Y[3 * c + ch] - pred[ch]) / f[ch])
                dz.settle(co, &st, pred, f, c, BR + 3 * j, 3 * j, False)
                for ch in range(3):
                    st.R[3 * c + ch] = pred[ch] + BR[3 * j + ch] * f[ch]
                to_world(co.frames, co.segments, st.card, st.R + 3 * c, st.sc, st.W + 3 * c)
            if pl.row_seg != NULL:
                segment_references(pl, co, &st, segref)
                if level_ref is not None:
                    for j in range(nbase - 1):
                        level_ref[s, j] = segref[j]
            for li in range(pl.levels):
                for row in range(pl.level_start[li], pl.level_start[li + 1]):
                    i = pl.idx[row]
                    predict_level(pl, co, &st, li, row, pred, f)
                    if pl.row_seg != NULL and dead_zone and dz.neighbour:
                        m = segref[pl.row_seg[row]]
                        dz.NB = &res[m, 0, 0] if m >= 0 else NULL
                    for ch in range(3):
                        LR[3 * row + ch] = <i64> rint((Y[3 * i + ch] - pred[ch]) / f[ch])
                    dz.settle(co, &st, pred, f, i, LR + 3 * row, 3 * (nbase + row), True)
                    for ch in range(3):
                        st.R[3 * i + ch] = pred[ch] + LR[3 * row + ch] * f[ch]
                    to_world(co.frames, co.segments, st.card, st.R + 3 * i, st.sc, st.W + 3 * i)
    free(segref)
    return 0


def level_differences(i64[:, :, ::1] res, const i64[:, ::1] level_ref, const i64[::1] row_seg, Py_ssize_t nbase):
    """The levels' rows of ``res [S, nbase + R, 3]`` made differences from those of their base segment's
    reference (``level_ref [S, nbase - 1]``, a strand before them, -1: none; ``row_seg [R]``; spec 4.3,
    ``level_guide``), in place: strands from the last, so that each reference is still whole when read.
    Integers wrap as int64."""
    cdef Py_ssize_t s, row, ch, rows = row_seg.shape[0]
    cdef i64 m
    if (res.shape[1] != nbase + rows or level_ref.shape[0] != res.shape[0] or level_ref.shape[1] != nbase - 1):
        raise ValueError("level_differences: mismatched shapes")
    for row in range(rows):
        if row_seg[row] < 0 or row_seg[row] >= nbase - 1:
            raise ValueError("level_differences: a row's base segment is out of range")
    for s in range(res.shape[0]):
        for row in range(nbase - 1):
            if level_ref[s, row] >= s:
                raise ValueError("level_differences: a reference is not a strand before its own")
    with nogil:
        for s in range(res.shape[0] - 1, -1, -1):
            for row in range(rows):
                m = level_ref[s, row_seg[row]]
                if m >= 0:
                    for ch in range(3):
                        res[s, nbase + row, ch] = <i64> (<uint64_t> res[s, nbase + row, ch]
                                                         - <uint64_t> res[m, nbase + row, ch])


def encode_rans(const uint8_t[:, ::1] sym, const int32_t[:, ::1] table, const i64[::1] active,
                const uint32_t[::1] flat_freq, const uint32_t[::1] flat_start, uint32_t[::1] states,
                uint16_t[::1] words):
    """rANS-code steps of symbols ``sym [N, L]`` under tables ``table [N, L]`` (lanes ``>= active[n]``
    idle at step ``n``), last step first, as :func:`decode_residuals` reads them back: the lanes'
    final states go to ``states [L]``, the words to the end of ``words`` (which must hold
    ``N * L``). Returns where the words begin."""
    cdef Py_ssize_t n, lane, pos = words.shape[0], lanes = states.shape[0]
    cdef uint64_t x, f
    cdef i64 k
    if sym.shape[1] != lanes or table.shape[0] != sym.shape[0] or table.shape[1] != lanes \
            or active.shape[0] != sym.shape[0] or words.shape[0] < sym.shape[0] * lanes:
        raise ValueError("encode_rans: mismatched shapes")
    with nogil:
        for lane in range(lanes):
            states[lane] = LOW
        for n in range(sym.shape[0] - 1, -1, -1):
            for lane in range(min(active[n], lanes) - 1, -1, -1):
                k = <i64> table[n, lane] * ALPHABET + sym[n, lane]
                x = states[lane]
                f = flat_freq[k]
                if x >= f << 20:  # ((LOW >> PROB_BITS) << 16) * f: emit a word, as the decoder reads one
                    pos -= 1
                    words[pos] = x & 0xFFFF
                    x >>= 16
                states[lane] = <uint32_t> (((x // f) << PROB_BITS) + x % f + flat_start[k])
    return pos


def pack_bits(const uint8_t[::1] width, const uint64_t[::1] value, uint8_t[::1] out):
    """Each ``value[i]``'s ``width[i]`` low bits (at most 64), most significant first, one after another
    into ``out`` from the most significant bit of its first byte; ``out`` must be zeroed and hold
    ``ceil(sum(width) / 8)`` bytes."""
    cdef Py_ssize_t i, n = width.shape[0]
    cdef uint64_t pos = 0, total = 0, v
    cdef int b
    if value.shape[0] != n:
        raise ValueError("pack_bits: mismatched shapes")
    for i in range(n):
        if width[i] > 64:
            raise ValueError("pack_bits: a width exceeds 64 bits")
        total += width[i]
    if <uint64_t> out.shape[0] != (total + 7) // 8:
        raise ValueError("pack_bits: the output does not have the bytes the widths need")
    with nogil:
        for i in range(n):
            v = value[i]
            for b in range(width[i] - 1, -1, -1):
                if (v >> b) & 1:
                    out[pos >> 3] |= <uint8_t> (0x80 >> (pos & 7))
                pos += 1


# --- the writer's strand order (spec 4.3, informative) ---------------------------------------------

def chain_order(const double[:, ::1] features, const i64[::1] by_card, const i64[::1] group_start, int window,
                i64[::1] out):
    """Within each group of ``by_card`` (strands sorted by card, then root v; group ``g`` is
    ``by_card[group_start[g]:group_start[g + 1]]``), a greedy chain: from the group's first strand,
    each next one is the most alike (L1 distance between ``features`` rows) among the first
    ``window`` strands not yet taken, in the group's order. Writes the chained strands to ``out``."""
    cdef Py_ssize_t g, a, n, k, i, j, best, prev, cur, pos = 0, f = features.shape[1], seen
    cdef double d, best_d
    cdef i64* nxt
    if by_card.shape[0] != out.shape[0] or group_start[group_start.shape[0] - 1] != by_card.shape[0]:
        raise ValueError("chain_order: mismatched shapes")
    for k in range(by_card.shape[0]):
        if by_card[k] < 0 or by_card[k] >= features.shape[0]:
            raise ValueError("chain_order: a strand index is out of range")
    nxt = <i64*> calloc(by_card.shape[0] + 1, sizeof(i64))
    if nxt == NULL:
        raise MemoryError()
    with nogil:
        for g in range(group_start.shape[0] - 1):
            a = group_start[g]
            n = group_start[g + 1] - a
            if n <= 0:
                continue
            # a linked list of the group's strands not yet taken, in order; slot n is its head
            for k in range(n):
                nxt[k] = k + 1 if k + 1 < n else -1
            cur = 0
            nxt[n] = nxt[0]  # the first strand is taken
            out[pos] = by_card[a]
            pos += 1
            for k in range(1, n):
                best = -1
                best_d = 0.0
                prev = n
                i = nxt[n]
                seen = 0
                while i >= 0 and seen < window:
                    d = 0.0
                    for j in range(f):
                        d = d + fabs(features[by_card[a + i], j] - features[by_card[a + cur], j])
                    if best < 0 or d < best_d:
                        best = i
                        best_d = d
                    i = nxt[i]
                    seen += 1
                # unlink best
                prev = n
                while nxt[prev] != best:
                    prev = nxt[prev]
                nxt[prev] = nxt[best]
                cur = best
                out[pos] = by_card[a + cur]
                pos += 1
    free(nxt)


# --- Interpolated strands (spec 4.5) -----------------------------------------------------------------

cdef inline void keep_nearest(i64* best, double* best_d, int k, i64 cand, double d) noexcept nogil:
    """Insert ``cand`` at distance ``d`` into the ``k`` nearest so far (sorted, nearest first, ties
    to the earlier candidate; ``best`` -1 where empty)."""
    cdef int i = k - 1
    if best[i] >= 0 and d >= best_d[i]:
        return
    while i > 0 and (best[i - 1] < 0 or d < best_d[i - 1]):
        best[i] = best[i - 1]
        best_d[i] = best_d[i - 1]
        i -= 1
    best[i] = cand
    best_d[i] = d


def nearest_roots(const double[:, ::1] roots, const i64[::1] order, const i64[:, ::1] lo, const i64[:, ::1] hi,
                  i64[:, ::1] out, Py_ssize_t first):
    """Per strand ``s = first + row`` (rows of ``lo``, ``hi``, ``out``), the ``out.shape[1]`` strands with
    the nearest roots (nearest first, -1 where fewer) among those listed in ``order[lo[row, c]:hi[row, c]]``
    over the cells ``c`` around its own (a grid: :func:`.children.root_candidates`), itself left out."""
    cdef Py_ssize_t row, c, t, n = lo.shape[0], k = out.shape[1]
    cdef i64 o, s
    cdef double d
    cdef double* best_d
    if hi.shape[0] != n or out.shape[0] != n or lo.shape[1] != hi.shape[1] or k < 1 or first < 0 \
            or first + n > roots.shape[0]:
        raise ValueError("nearest_roots: mismatched shapes")
    for row in range(n):
        for c in range(lo.shape[1]):
            if lo[row, c] < 0 or hi[row, c] > order.shape[0]:
                raise ValueError("nearest_roots: a cell is out of range")
    for t in range(order.shape[0]):
        if order[t] < 0 or order[t] >= roots.shape[0]:
            raise ValueError("nearest_roots: a strand index is out of range")
    best_d = <double*> calloc(k, sizeof(double))
    if best_d == NULL:
        raise MemoryError()
    with nogil:
        for row in range(n):
            s = first + row
            for t in range(k):
                out[row, t] = -1
            for c in range(lo.shape[1]):
                for t in range(lo[row, c], hi[row, c]):
                    o = order[t]
                    if o == s:
                        continue
                    d = ((roots[o, 0] - roots[s, 0]) * (roots[o, 0] - roots[s, 0])
                         + (roots[o, 1] - roots[s, 1]) * (roots[o, 1] - roots[s, 1])
                         + (roots[o, 2] - roots[s, 2]) * (roots[o, 2] - roots[s, 2]))
                    keep_nearest(&out[row, 0], best_d, <int> k, o, d)
    free(best_d)


cdef double THIN = 0.9999  # roots this near a line (cos^2 of their angle at the first) leave the weights to the points


cdef inline bint solve2(double g11, double g12, double g22, double h1, double h2, double* a, double* b) noexcept nogil:
    """``[g11 g12; g12 g22] (a, b) = (h1, h2)``; False where the system is singular."""
    cdef double det = g11 * g22 - g12 * g12
    if not (fabs(det) > 1e-12 * (g11 * g22) and g11 > 0 and g22 > 0):
        return False
    a[0] = (g22 * h1 - g12 * h2) / det
    b[0] = (g11 * h2 - g12 * h1) / det
    return True


cdef inline double blend_miss(const double[:, ::1] desc, const double[:, ::1] tangent, i64 s, i64 i, i64 j,
                              i64 l, double wj, double wl, double limit) noexcept nogil:
    """The largest squared distance across the strand (along ``tangent``, its unit tangents, left out:
    a blend resampled at even arc length slides along it), over the descriptor's points, between
    strand ``s`` and the blend ``(1 - wj - wl) i + wj j + wl l``; stops once above ``limit``."""
    cdef Py_ssize_t f, c, n = desc.shape[1]
    cdef double worst = 0.0, d2, e, along
    cdef double wi = 1.0 - wj - wl
    for f in range(n - 3, -1, -3):  # from the tip, where blends part most: most stop sooner
        d2 = 0.0
        along = 0.0
        for c in range(f, f + 3):
            e = desc[s, c] - wi * desc[i, c] - wj * desc[j, c] - wl * desc[l, c]
            d2 = d2 + e * e
            along = along + e * tangent[s, c]
        d2 = d2 - along * along
        if d2 > worst:
            worst = d2
            if worst > limit:
                break
    return worst


cdef inline double dot_rows(const double[:, ::1] x, i64 a, i64 a0, i64 b, i64 b0) noexcept nogil:
    """``(x[a] - x[a0]) . (x[b] - x[b0])``."""
    cdef Py_ssize_t c
    cdef double t = 0.0
    for c in range(x.shape[1]):
        t = t + (x[a, c] - x[a0, c]) * (x[b, c] - x[b0, c])
    return t


def best_blends(const double[:, ::1] roots, const double[:, ::1] desc, const double[:, ::1] tangent,
                const i64[::1] strands, const i64[:, ::1] cand,
                const uint8_t[::1] usable, double root_tol, double slack, double good, i64[:, ::1] parents,
                double[:, ::1] weights, double[::1] miss):
    """Per strand ``s = strands[row]`` (rows of ``cand``, ``parents``, ``weights``, ``miss``), the blend
    of two or three ``usable`` strands among its candidates ``cand[row]`` that best predicts it: over
    the pairs and triples whose roots blend to within ``root_tol`` of its root with weights of at least
    ``-slack`` (and at most ``1 + slack``), with the weights that blend the roots so (or, where the
    three roots lie nearly in a line, the least-squares weights of ``desc``), the one whose largest
    distance across the strand at the points of ``desc`` (rows of points x 3; ``tangent``, the
    strand's unit tangents there) is least, or the first within ``good``. Writes the three parents (a
    pair repeats its second), their weights and that distance (``miss``; infinity where none
    qualifies, parents -1)."""
    cdef Py_ssize_t row, a, b, c, n = cand.shape[0], k = cand.shape[1]
    cdef i64 i, j, l, s
    cdef double rtol2 = root_tol * root_tol, good2 = good * good, best, d2, gjj, gjl, gll, hj, hl, wj, wl, r2, xx, t
    cdef double* dist  # [k, k] the candidates' roots' squared distances, then [k] theirs to the strand's
    if (roots.shape[0] != desc.shape[0] or usable.shape[0] != desc.shape[0] or parents.shape[0] != n
            or tangent.shape[0] != desc.shape[0] or tangent.shape[1] != desc.shape[1]
            or weights.shape[0] != n or miss.shape[0] != n or parents.shape[1] != 3 or weights.shape[1] != 3
            or desc.shape[1] % 3 != 0 or strands.shape[0] != n or roots.shape[1] != 3):
        raise ValueError("best_blends: mismatched shapes")
    for row in range(n):
        if strands[row] < 0 or strands[row] >= roots.shape[0]:
            raise ValueError("best_blends: a strand index is out of range")
        for a in range(k):
            if cand[row, a] >= roots.shape[0] or cand[row, a] < -1:
                raise ValueError("best_blends: a candidate is out of range")
    dist = <double*> calloc(k * k + k, sizeof(double))
    if dist == NULL:
        raise MemoryError()
    with nogil:
        for row in range(n):
            s = strands[row]
            best = INFINITY
            parents[row, 0] = -1
            parents[row, 1] = -1
            parents[row, 2] = -1
            for a in range(k):  # (sides from squared distances: the roots' dot products below follow)
                i = cand[row, a]
                if i < 0:
                    continue
                dist[k * k + a] = dot_rows(roots, s, i, s, i)
                for b in range(a + 1, k):
                    if cand[row, b] >= 0:
                        t = dot_rows(roots, cand[row, b], i, cand[row, b], i)
                        dist[a * k + b] = t
                        dist[b * k + a] = t
            for a in range(k):
                i = cand[row, a]
                if i < 0 or not usable[i] or best <= good2:
                    continue
                xx = dist[k * k + a]
                for b in range(a + 1, k):
                    j = cand[row, b]
                    if j < 0 or not usable[j] or best <= good2:
                        continue
                    gjj = dist[a * k + b]
                    hj = (xx + gjj - dist[k * k + b]) / 2
                    if gjj > 0:  # the pair i, j
                        wj = hj / gjj
                        if -slack <= wj <= 1 + slack and xx - wj * hj <= rtol2:
                            d2 = blend_miss(desc, tangent, s, i, j, j, wj, 0.0, best)
                            if d2 < best:
                                best = d2
                                parents[row, 0], parents[row, 1], parents[row, 2] = i, j, j
                                weights[row, 0], weights[row, 1], weights[row, 2] = 1 - wj, wj, 0.0
                    for c in range(b + 1, k):
                        l = cand[row, c]
                        if l < 0 or not usable[l]:
                            continue
                        gll = dist[a * k + c]
                        gjl = (gjj + gll - dist[b * k + c]) / 2
                        hl = (xx + gll - dist[k * k + c]) / 2
                        if gjl * gjl < THIN * gjj * gll:  # the roots' blend says the weights
                            if not solve2(gjj, gjl, gll, hj, hl, &wj, &wl):
                                continue
                        elif not solve2(dot_rows(desc, j, i, j, i), dot_rows(desc, j, i, l, i),
                                        dot_rows(desc, l, i, l, i), dot_rows(desc, s, i, j, i),
                                        dot_rows(desc, s, i, l, i), &wj, &wl):
                            continue  # roots in a line: the points' least squares do
                        if wj < -slack or wl < -slack or wj + wl > 1 + slack:
                            continue
                        r2 = xx - 2 * (wj * hj + wl * hl) + wj * wj * gjj + 2 * wj * wl * gjl + wl * wl * gll
                        if r2 > rtol2:  # (the squared distance left at the root)
                            continue
                        d2 = blend_miss(desc, tangent, s, i, j, l, wj, wl, best)
                        if d2 < best:
                            best = d2
                            parents[row, 0], parents[row, 1], parents[row, 2] = i, j, l
                            weights[row, 0], weights[row, 1], weights[row, 2] = 1 - wj - wl, wj, wl
            miss[row] = sqrt(best)
    free(dist)


def blend_misses(const double[:, :, ::1] guides, const i64[:, ::1] parents, const i64[:, ::1] weights,
                 int weight_one, const uint8_t[::1] respaced, const double[:, :, ::1] targets, double[::1] miss):
    """Per child, the largest distance between its :func:`blend_strands` points and ``targets``."""
    cdef Py_ssize_t s, i, c, n = parents.shape[0], p = guides.shape[1]
    cdef double* blend
    cdef double* length
    cdef double* one
    cdef double d2, e, worst
    check_blends(guides, parents, weights, weight_one, respaced, n, p)
    if targets.shape[0] != n or targets.shape[1] != p or targets.shape[2] != 3 or miss.shape[0] != n:
        raise ValueError("blend_misses: mismatched shapes")
    blend = <double*> calloc(3 * p, sizeof(double))
    length = <double*> calloc(p, sizeof(double))
    one = <double*> calloc(3 * p, sizeof(double))
    if blend == NULL or length == NULL or one == NULL:
        free(blend)
        free(length)
        free(one)
        raise MemoryError()
    with nogil:
        for s in range(n):
            blend_one(guides, &parents[s, 0], &weights[s, 0], weight_one, respaced[s], blend, length, one)
            worst = 0.0
            for i in range(p):
                d2 = 0.0
                for c in range(3):
                    e = one[3 * i + c] - targets[s, i, c]
                    d2 = d2 + e * e
                if d2 > worst:
                    worst = d2
            miss[s] = sqrt(worst)
    free(blend)
    free(length)
    free(one)


def fit_blends(const double[:, :, ::1] targets, const double[:, :, ::1] sources, const i64[:, ::1] parents,
               double[:, ::1] weights):
    """Per row, the weights (summing to 1) of the blend of ``sources[parents[row]]`` nearest
    ``targets[row]`` by least squares over all points; where the three do not span a plane (a pair:
    the third parent repeats the second), the pair's, the third weight 0."""
    cdef Py_ssize_t r, i, c, n = targets.shape[0], p = targets.shape[1]
    cdef i64 a, b, d
    cdef double e1, e2, x, g11, g12, g22, h1, h2, w1, w2
    if (sources.shape[1] != p or targets.shape[2] != 3 or sources.shape[2] != 3 or parents.shape[0] != n
            or parents.shape[1] != 3 or weights.shape[0] != n or weights.shape[1] != 3):
        raise ValueError("fit_blends: mismatched shapes")
    for r in range(n):
        for c in range(3):
            if parents[r, c] < 0 or parents[r, c] >= sources.shape[0]:
                raise ValueError("fit_blends: a parent is out of range")
    with nogil:
        for r in range(n):
            a, b, d = parents[r, 0], parents[r, 1], parents[r, 2]
            g11 = g12 = g22 = h1 = h2 = 0.0
            for i in range(p):
                for c in range(3):
                    e1 = sources[b, i, c] - sources[a, i, c]
                    e2 = sources[d, i, c] - sources[a, i, c]
                    x = targets[r, i, c] - sources[a, i, c]
                    g11 = g11 + e1 * e1
                    g12 = g12 + e1 * e2
                    g22 = g22 + e2 * e2
                    h1 = h1 + e1 * x
                    h2 = h2 + e2 * x
            if not solve2(g11, g12, g22, h1, h2, &w1, &w2):
                w1 = h1 / g11 if g11 > 0 else 0.0
                w2 = 0.0
            weights[r, 0] = 1.0 - w1 - w2
            weights[r, 1] = w1
            weights[r, 2] = w2
