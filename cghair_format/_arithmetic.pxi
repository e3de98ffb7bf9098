# The arithmetic and the searches of spec sections 4.3, 4.5 and 6.1 that the decoder's kernels
# (_decoder.pyx) and the writer's (_writer.pyx) share, included in both: the writer predicts with
# exactly the decoder's functions.

# The spec's decoding arithmetic (spec 4, "Arithmetic"): each float64 operation rounded on its own, in
# the order written. No fused multiply-add, whatever flags the build passes (GCC and Clang honour these
# pragmas for every function below; setup.py also passes -ffp-contract=off; tests/format/test_fma_build.py
# builds with -ffp-contract=fast -mfma and checks that every vector decodes the same).
cdef extern from *:
    """
    #if defined(__clang__)
    #pragma clang fp contract(off)
    #elif defined(__GNUC__)
    #pragma GCC optimize ("fp-contract=off")
    #endif
    """

from libc.float cimport FLT_MAX
from libc.math cimport INFINITY, fabs, floor, isfinite, rint, sqrt
from libc.stdint cimport int32_t, uint8_t, uint16_t, uint32_t, uint64_t
from libc.stdlib cimport calloc, free

ctypedef long long i64


cdef struct Frame:  # a card triangle as an affine frame (geometry.CardMap): 18 doubles
    double a[3]
    double ef[3]
    double ev[3]
    double na[3]
    double nef[3]
    double nev[3]


cdef inline double dot3(const double* a, const double* b) noexcept nogil:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


cdef inline void cross3(const double* a, const double* b, double* out) noexcept nogil:
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


cdef inline void card_map(const double* frames, int m, i64 card, const double* uvd, double* x,
                          double* ju, double* jv, double* jd) noexcept nogil:
    """World point ``x`` of card coordinates ``uvd`` on ``card``; with ``ju`` not NULL also the
    Jacobian columns d x / d(u, v, delta)."""
    cdef double s = uvd[0] * m
    cdef double k = floor(s)
    if not (k >= 0):  # also NaN
        k = 0
    if k > m - 1:
        k = m - 1
    cdef double f = s - k
    cdef int upper = f + uvd[1] > 1
    cdef double g = uvd[1] - upper
    cdef const Frame* fr = <const Frame*> (frames + 18 * (card * 2 * m + 2 * <i64> k + upper))
    cdef double n[3]
    cdef double nh[3]
    cdef int i
    for i in range(3):
        n[i] = fr.na[i] + f * fr.nef[i] + g * fr.nev[i]
    cdef double length = sqrt(dot3(n, n))
    if length < 1e-30:
        length = 1e-30
    for i in range(3):
        nh[i] = n[i] / length
    cdef double delta = uvd[2]
    for i in range(3):
        x[i] = fr.a[i] + f * fr.ef[i] + g * fr.ev[i] + delta * nh[i]
    if ju == NULL:
        return
    cdef double pf = dot3(nh, fr.nef)
    cdef double pv = dot3(nh, fr.nev)
    for i in range(3):
        ju[i] = m * (fr.ef[i] + delta * ((fr.nef[i] - nh[i] * pf) / length))
        jv[i] = fr.ev[i] + delta * ((fr.nev[i] - nh[i] * pv) / length)
        jd[i] = nh[i]


cdef inline void solve3(const double* a, const double* b, const double* c, const double* r,
                        double* out) noexcept nogil:
    """``[a b c] out = r`` by Cramer's rule; a singular system (|det| <= 1e-30) gives 0."""
    cdef double bc[3]
    cdef double ca[3]
    cdef double ab[3]
    cross3(b, c, bc)
    cross3(c, a, ca)
    cross3(a, b, ab)
    cdef double det = dot3(a, bc)
    if not (fabs(det) > 1e-30):
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 0.0
        return
    out[0] = dot3(r, bc) / det
    out[1] = dot3(r, ca) / det
    out[2] = dot3(r, ab) / det


cdef inline void to_world(const double* frames, int m, i64 card, const double* scaled, const double* sc,
                          double* x) noexcept nogil:
    """World point ``x`` of scaled card coordinates (``scaled / sc``, spec 4.3: ``y / g``)."""
    cdef double uvd[3]
    uvd[0] = scaled[0] / sc[0]
    uvd[1] = scaled[1] / sc[1]
    uvd[2] = scaled[2] / sc[2]
    card_map(frames, m, card, uvd, x, NULL, NULL, NULL)


# A Newton search stops once the miss is within a hundredth of a step: (miss / q)^2 <= 1e-4 (spec 4.3)
cdef double NEWTON_CLOSE2 = 1e-4


cdef inline double newton_solve(const double* frames, int m, i64 card, const double* goal, int steps,
                                int halvings, double* c, double per_unit2, double* j) noexcept nogil:
    """Up to ``steps`` Newton steps on ``map(card, c) = goal`` from the card coordinates ``c`` (in
    place), each searched back (spec 4.3): the full step, else up to ``halvings`` times half the last,
    the first that maps nearer ``goal`` than the point it starts from; none (or a step that is not
    finite) ends the search, and so does a miss whose square times ``per_unit2`` is at most
    NEWTON_CLOSE2 (``per_unit2`` 0: never). Returns the squared distance left; ``j [9]`` gets the
    Jacobian columns at the final ``c``."""
    cdef double x[3]
    cdef double cand[3]
    cdef double jc[9]
    cdef double miss[3]
    cdef double sol[3]
    cdef double m2, d2, t
    cdef int i, step, h, ok
    card_map(frames, m, card, c, x, j, j + 3, j + 6)
    for i in range(3):
        miss[i] = goal[i] - x[i]
    m2 = dot3(miss, miss)
    for step in range(steps):
        if per_unit2 > 0 and m2 * per_unit2 <= NEWTON_CLOSE2:
            break
        solve3(j, j + 3, j + 6, miss, sol)
        if not (isfinite(sol[0]) and isfinite(sol[1]) and isfinite(sol[2])):
            break
        t = 1.0
        ok = 0
        for h in range(halvings + 1):
            for i in range(3):
                cand[i] = c[i] + t * sol[i]
            card_map(frames, m, card, cand, x, jc, jc + 3, jc + 6)
            for i in range(3):
                miss[i] = goal[i] - x[i]
            d2 = dot3(miss, miss)
            if d2 < m2:
                ok = 1
                break
            t = 0.5 * t
        if not ok:
            break
        m2 = d2
        for i in range(3):
            c[i] = cand[i]
        for i in range(9):
            j[i] = jc[i]
    return m2


cdef inline void newton(const double* frames, int m, i64 card, const double* sc, const double* goal, int steps,
                        int halvings, double* p, double* j) noexcept nogil:
    """Spec 4.3's ``place`` without the stretch: :func:`newton_solve` from the scaled card coordinates
    ``p / sc`` (stopping within a hundredth of a step of ``goal``: ``sc[2]`` is 1 / q), ``p`` then the
    result times ``sc`` where that is finite, else kept; ``j [9]`` gets the Jacobian columns at the card
    coordinates ``p / sc``."""
    cdef double c[3]
    cdef double x[3]
    cdef int i
    for i in range(3):
        c[i] = p[i] / sc[i]
    newton_solve(frames, m, card, goal, steps, halvings, c, sc[2] * sc[2], j)
    for i in range(3):
        x[i] = c[i] * sc[i]
    if isfinite(x[0]) and isfinite(x[1]) and isfinite(x[2]):
        for i in range(3):
            p[i] = x[i]
        return
    for i in range(3):
        c[i] = p[i] / sc[i]
    card_map(frames, m, card, c, x, j, j + 3, j + 6)


cdef inline double step_ratio(const double* a, const double* b, const double* na, const double* nb) noexcept nogil:
    """How much longer the step ``a -> b`` is than the step ``na -> nb`` (world points), within
    [0.5, 2]; 1 where the second has no length (spec 4.3, ``base_guide`` 2)."""
    cdef double d[3]
    cdef double e[3]
    cdef double r = 1.0
    cdef int i
    for i in range(3):
        d[i] = b[i] - a[i]
        e[i] = nb[i] - na[i]
    if dot3(e, e) > 0:
        r = sqrt(dot3(d, d) / dot3(e, e))
    if not (r >= 0.5):  # also NaN
        r = 0.5
    if r > 2.0:
        r = 2.0
    return r


# base_guide 3 and level_guide (spec 4.3): a guided base sample after the first takes its step, and a
# base segment's refinement residuals are stored as differences from those, of the most alike of the
# CANDIDATES strands before it on its card (a decoder keeps their scratch and its own), where
# unlikeness weighs the strands' distance by UNLIKE_PLACE against how their steps differ
cdef enum:
    CANDIDATES = 32
cdef double UNLIKE_PLACE = 1.0 / 32
cdef double ORIGIN[3]  # zero, as C's static storage starts
GUIDE_CANDIDATES = CANDIDATES
SCRATCH_STRANDS = CANDIDATES + 1


cdef inline double diff2(const double* a, const double* b, const double* c, const double* d) noexcept nogil:
    """``|(b - a) - (d - c)|^2`` of world points."""
    cdef double e, s = 0.0
    cdef int i
    for i in range(3):
        e = (b[i] - a[i]) - (d[i] - c[i])
        s = s + e * e
    return s


cdef inline double unlikeness(const double* w, const double* wm, const i64* base, Py_ssize_t first,
                              Py_ssize_t last, Py_ssize_t at, double below) noexcept nogil:
    """How unlike the strand with world points ``wm`` is to the one with ``w`` (spec 4.3, ``U``): the
    squared differences of their steps ``base[k] -> base[k + 1]`` for ``k = first .. last``, then
    UNLIKE_PLACE times their squared distance at ``base[at]``. Stops (returning no less) once the sum
    reaches ``below``."""
    cdef double d = 0.0
    cdef Py_ssize_t k
    for k in range(first, last + 1):
        d = d + diff2(w + 3 * base[k], w + 3 * base[k + 1], wm + 3 * base[k], wm + 3 * base[k + 1])
        if d >= below:
            return d
    return d + UNLIKE_PLACE * diff2(ORIGIN, w + 3 * base[at], ORIGIN, wm + 3 * base[at])


cdef inline i64 scratch_row(Py_ssize_t t, const i64[::1] strands_to_code, bint scratch) noexcept nogil:
    """The row of ``rec`` and ``world`` holding the strand at position ``t``: its own, or decoding, one
    of the scratch's SCRATCH_STRANDS in turn."""
    return (t % (CANDIDATES + 1)) if scratch else strands_to_code[t]


cdef inline Py_ssize_t most_alike(Py_ssize_t t, const i64[::1] strands_to_code, const i64[::1] strand_card,
                                  const double[:, :, ::1] world, bint scratch, const double* w, const i64* base,
                                  Py_ssize_t first, Py_ssize_t last, Py_ssize_t at) noexcept nogil:
    """Of the CANDIDATES strands before position ``t`` of ``strands_to_code`` on its card (the one at
    ``t - 1`` must be), the position of the most alike to the strand with world points ``w`` by
    :func:`unlikeness` over ``first, last, at``: the neighbour ``t - 1``, unless one farther back is
    less unlike (strictly: a tie, or NaN, keeps the nearer)."""
    cdef i64 card = strand_card[strands_to_code[t]]
    cdef Py_ssize_t k, pick = t - 1
    cdef double d, best = unlikeness(w, &world[scratch_row(t - 1, strands_to_code, scratch), 0, 0], base, first,
                                     last, at, INFINITY)
    k = t - 2
    while k >= 0 and k >= t - CANDIDATES and strand_card[strands_to_code[k]] == card:
        d = unlikeness(w, &world[scratch_row(k, strands_to_code, scratch), 0, 0], base, first, last, at, best)
        if d < best:
            best = d
            pick = k
        k -= 1
    return pick


cdef inline void residual_steps(const double* j, const double* sc, double stretch_max, double* f) noexcept nogil:
    """The steps ``f`` in scaled card coordinates of a residual whose prediction a Newton search made (a
    refinement sample's, a guided base sample's; spec 4.3), from the Jacobian columns ``j [9]`` at that
    prediction: on u and v, the card's scale over the local one
    (``g / (|J| g_d)``: one step then moves the point by about ``q``), within [1, ``stretch_max``];
    1 on delta."""
    cdef double v
    cdef int ch
    f[2] = 1.0
    for ch in range(2):
        v = sc[ch] / (sqrt(dot3(j + 3 * ch, j + 3 * ch)) * sc[2])
        if v > stretch_max:  # also inf
            v = stretch_max
        if not (v >= 1.0):  # also NaN, and stretch_max 1
            v = 1.0
        f[ch] = v


cdef check_cards(const i64[::1] card, Py_ssize_t triangles, int segments):
    """Every card index must have its triangles in ``frames``: the kernels read them unchecked."""
    cdef Py_ssize_t i, cards = triangles // (2 * segments) if segments > 0 else 0
    for i in range(card.shape[0]):
        if card[i] < 0 or card[i] >= cards:
            raise ValueError(f"card index {card[i]} outside [0, {cards})")


# --- the recurrence of spec 4.3, one sample at a time (the decoder's, which the writer runs too) ----

cdef int check_plan(const i64[::1] strands_to_code, const double[:, ::1] frames, int segments,
                    const i64[::1] strand_card, const double[:, ::1] scale, const i64[::1] base,
                    const i64[::1] level_start, const i64[::1] level_taps, const i64[::1] idx, const i64[:, ::1] nb,
                    const double[:, ::1] wt, double stretch_max, const i64[:, :, ::1] res, const i64[::1] row_seg,
                    Py_ssize_t rows, Py_ssize_t points, double[:, :, ::1] rec, double[:, :, ::1] world) except -1:
    """The arguments :func:`decode_strands` and :func:`encode_strands` share, checked (the kernels read
    them unchecked): ``rec`` and ``world`` hold ``rows`` strands of ``points``."""
    cdef Py_ssize_t t, row, li, nbase = base.shape[0], levels = level_start.shape[0] - 1
    check_cards(strand_card, frames.shape[0], segments)
    if (frames.shape[1] != 18 or scale.shape[0] != strand_card.shape[0] or scale.shape[1] != 3
            or tuple(rec.shape)[:3] != (rows, points, 3) or tuple(world.shape)[:3] != (rows, points, 3)
            or tuple(res.shape)[:3] != (strand_card.shape[0], nbase + idx.shape[0], 3)
            or nb.shape[0] != idx.shape[0] or wt.shape[0] != idx.shape[0] or nb.shape[1] != wt.shape[1]
            or level_taps.shape[0] != levels or level_start[levels] != idx.shape[0]):
        raise ValueError("strand recurrence: mismatched shapes")
    for t in range(strands_to_code.shape[0]):
        if strands_to_code[t] < 0 or strands_to_code[t] >= strand_card.shape[0]:
            raise ValueError("strand recurrence: a strand index is out of range")
    if not stretch_max >= 1.0:
        raise ValueError("strand recurrence: stretch_max must be at least 1")
    for li in range(levels):
        if level_taps[li] < 0 or level_taps[li] > nb.shape[1]:
            raise ValueError("strand recurrence: a level's interpolation width exceeds its neighbour columns")
    if row_seg is not None:
        if row_seg.shape[0] != idx.shape[0]:
            raise ValueError("strand recurrence: mismatched shapes")
        for row in range(idx.shape[0]):
            if row_seg[row] < 0 or row_seg[row] >= nbase - 1:
                raise ValueError("strand recurrence: a row's base segment is out of range")
    return 0


cdef inline void predict_base(Py_ssize_t t, Py_ssize_t j, const i64[::1] strands_to_code, const i64[::1] strand_card,
                              double[:, :, ::1] rec, double[:, :, ::1] world, bint scratch, const double* fr,
                              int segments, i64 card, const double* sc, const i64[::1] base,
                              const i64[::1] base_order, int base_guide, int newton_steps, int newton_halvings,
                              double stretch_max, const double* R, const double* W, const double* RN,
                              const double* WN, double* pred, double* f) noexcept nogil:
    """Base sample ``j``'s prediction ``pred`` and residual steps ``f`` (spec 4.3) for the strand at
    position ``t`` with scaled card coordinates ``R`` and world points ``W`` so far. With a card
    neighbour (``RN``, ``WN`` not NULL; ``base_guide`` > 0): its root, then its step (with 2, scaled
    as the previous steps compare; with 3, after the first, the step of the most alike strand before
    it), in world space, carried onto the card by the searched Newton steps. Else the strand's own
    base samples, per channel (spec 4.1)."""
    cdef i64 a, b, c = base[j]
    cdef double rho
    cdef const double* RM
    cdef const double* WM
    cdef double goal[3]
    cdef double jac[9]
    cdef int ch
    f[0] = 1.0
    f[1] = 1.0
    f[2] = 1.0
    if RN != NULL and j == 0:  # the neighbour's root
        for ch in range(3):
            pred[ch] = RN[3 * c + ch]
    elif RN != NULL:  # the neighbour's step, in world space, onto the card
        b = base[j - 1]
        rho = 1.0
        if base_guide == 2 and j > 1:  # scaled as the previous steps compare
            a = base[j - 2]
            rho = step_ratio(W + 3 * a, W + 3 * b, WN + 3 * a, WN + 3 * b)
        RM = RN
        WM = WN
        if base_guide == 3 and j > 1:  # the most alike strand of those before it
            a = scratch_row(most_alike(t, strands_to_code, strand_card, world, scratch, W, &base[0],
                                       max(j - 3, 0), j - 2, j - 1), strands_to_code, scratch)
            RM = &rec[a, 0, 0]
            WM = &world[a, 0, 0]
        for ch in range(3):
            pred[ch] = R[3 * b + ch] + rho * (RM[3 * c + ch] - RM[3 * b + ch])
            goal[ch] = W[3 * b + ch] + rho * (WM[3 * c + ch] - WM[3 * b + ch])
        newton(fr, segments, card, sc, goal, newton_steps, newton_halvings, pred, jac)
        residual_steps(jac, sc, stretch_max, f)
    else:  # the strand's own base samples, per channel (spec 4.1)
        for ch in range(3):
            if j == 0:
                pred[ch] = 0.0
            elif j == 1 or base_order[ch] == 1:
                pred[ch] = R[3 * base[j - 1] + ch]
            else:
                a = base[j - 2]
                b = base[j - 1]
                rho = <double> (c - b) / <double> (b - a)
                pred[ch] = R[3 * b + ch] + (R[3 * b + ch] - R[3 * a + ch]) * rho


cdef inline void segment_references(Py_ssize_t t, const i64[::1] strands_to_code, const i64[::1] strand_card,
                                    const double[:, :, ::1] world, bint scratch, const double* W,
                                    const i64[::1] base, bint neighbour, i64* segref) noexcept nogil:
    """``level_guide`` (spec 4.3.1): per base segment ``k``, ``segref[k]``, the strand whose refinement
    residuals the segment's are differences from: the most alike of those before the strand at
    position ``t`` on its card (-1 without a card ``neighbour``)."""
    cdef Py_ssize_t k, nbase = base.shape[0]
    for k in range(nbase - 1):
        segref[k] = -1
        if neighbour:
            segref[k] = strands_to_code[most_alike(t, strands_to_code, strand_card, world, scratch, W, &base[0],
                                                   max(k - 1, 0), min(k + 1, nbase - 2), k + 1)]


cdef inline void predict_level(Py_ssize_t row, Py_ssize_t taps, const i64[:, ::1] nb, const double[:, ::1] wt,
                               const double* R, const double* W, const double* fr, int segments, i64 card,
                               const double* sc, int newton_steps, int newton_halvings, double stretch_max,
                               double* pred, double* f) noexcept nogil:
    """A refinement sample's prediction ``pred`` and residual steps ``f`` (spec 4.3): the Lagrange
    interpolation (the first ``taps`` columns of row ``row`` of ``nb`` and ``wt``, left to right) of
    the scaled card coordinates ``R`` and of the world points ``W``, the second carried onto the card
    by the searched Newton steps from the first."""
    cdef double goal[3]
    cdef double jac[9]
    cdef double w
    cdef Py_ssize_t k, j
    cdef int ch
    for ch in range(3):
        pred[ch] = 0.0
        goal[ch] = 0.0
    for k in range(taps):
        w = wt[row, k]
        j = 3 * nb[row, k]
        for ch in range(3):
            pred[ch] = pred[ch] + R[j + ch] * w
            goal[ch] = goal[ch] + W[j + ch] * w
    newton(fr, segments, card, sc, goal, newton_steps, newton_halvings, pred, jac)
    residual_steps(jac, sc, stretch_max, f)


cdef inline const double* card_neighbour(Py_ssize_t t, const i64[::1] strands_to_code, const i64[::1] strand_card,
                                          double[:, :, ::1] rows, bint scratch) noexcept nogil:
    """The row of ``rows`` (``rec`` or ``world``) of the strand before position ``t`` when it lies on the
    same card (the card neighbour, spec 4.3.1), else NULL."""
    if t > 0 and strand_card[strands_to_code[t - 1]] == strand_card[strands_to_code[t]]:
        return &rows[scratch_row(t - 1, strands_to_code, scratch), 0, 0]
    return NULL


cdef inline void respace(const double* x, int p, double* length, double* out) noexcept nogil:
    """``out [p, 3]``: the polyline ``x [p, 3]`` resampled at even arc length (spec 4.5)."""
    cdef int i, c, seg = 0
    cdef double target, t, d, e
    length[0] = 0.0
    for i in range(1, p):
        d = 0.0
        for c in range(3):
            e = x[3 * i + c] - x[3 * (i - 1) + c]
            d = d + e * e
        length[i] = length[i - 1] + sqrt(d)
    for i in range(p):
        if i == p - 1:
            for c in range(3):
                out[3 * i + c] = x[3 * i + c]
            continue
        target = length[p - 1] * i / (p - 1)
        while seg < p - 2 and length[seg + 1] < target:
            seg += 1
        d = length[seg + 1] - length[seg]
        t = (target - length[seg]) / d if d > 0 else 0.0
        for c in range(3):
            out[3 * i + c] = x[3 * seg + c] + t * (x[3 * (seg + 1) + c] - x[3 * seg + c])


cdef inline void blend_one(const double[:, :, ::1] guides, const i64* parents, const i64* weights, int weight_one,
                           bint respaced, double* blend, double* length, double* out) noexcept nogil:
    """One child's points (:func:`blend_strands`) into ``out [P, 3]`` (``blend [P, 3]``, ``length [P]``:
    scratch)."""
    cdef Py_ssize_t i, c, p = guides.shape[1]
    cdef double w0 = <double> weights[0] / weight_one, w1 = <double> weights[1] / weight_one
    cdef double w2 = <double> weights[2] / weight_one
    cdef double* target = blend if respaced else out
    for i in range(p):
        for c in range(3):
            target[3 * i + c] = (w0 * guides[parents[0], i, c] + w1 * guides[parents[1], i, c]
                                 + w2 * guides[parents[2], i, c])
    if respaced:
        respace(blend, <int> p, length, out)


cdef check_blends(const double[:, :, ::1] guides, const i64[:, ::1] parents, const i64[:, ::1] weights,
                  int weight_one, const uint8_t[::1] respaced, Py_ssize_t n, Py_ssize_t p):
    cdef Py_ssize_t s, c
    if (parents.shape[0] != n or parents.shape[1] != 3 or weights.shape[0] != n or weights.shape[1] != 3
            or respaced.shape[0] != n or guides.shape[1] != p or guides.shape[2] != 3 or p < 2 or weight_one <= 0):
        raise ValueError("blend: mismatched shapes")
    for s in range(n):
        for c in range(3):
            if parents[s, c] < 0 or parents[s, c] >= guides.shape[0]:
                raise ValueError("blend: a parent is out of range")


# --- the STRD coder's constants (spec 4.3.2) -------------------------------------------------------

cdef enum:  # rans.py, residual_coder.py
    DIRECT = 16
    ALPHABET = 76
    PROB_BITS = 12
    LOW = 65536
    PREV_CLASSES = 8
    OTHER_CLASSES = 4
    CONTEXTS = 32
