# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of the codec: the per-point recurrences that numpy can only run as long chains of
whole-array temporaries. Each follows the spec's pseudocode one point at a time, releases the GIL,
and is called on independent blocks of strands from several threads (:mod:`.parallel`).

- :func:`map_points`: the card-to-world mapping (spec 6.1) of many points.
- :func:`run_strands`: the world-guided predictive coding of strand points (spec 4.3), encoding
  (residuals from scaled card coordinates) or decoding (scaled card coordinates from residuals).
- :func:`undo_neighbour`: the neighbour prediction across the strands of a card (spec 4.3), undone.
- :func:`decode_residuals`: the STRD token stream and extra bits (spec 4.3.2), decoded.
- :func:`encode_rans`: the STRD tokens, rANS-coded (the writer's side of spec 4.3.2).
- :func:`pack_bits`: the extra bits, packed (the writer's side of spec 4.3.2).
- :func:`blend_strands`, :func:`place_points`: interpolated strands' points and card coordinates
  (spec 4.5); the writer's search for them: :func:`nearest_roots`, :func:`best_blends`,
  :func:`fit_blends`, :func:`blend_misses`.
"""

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


def run_strands(const i64[::1] strands_to_code, const double[:, ::1] frames, int segments,
                const i64[::1] strand_card, const double[:, ::1] scale,
                const i64[::1] base, const i64[::1] base_order, const i64[::1] level_start,
                const i64[::1] level_taps, const i64[::1] idx,
                const i64[:, ::1] nb, const double[:, ::1] wt, int newton_steps, int newton_halvings,
                double stretch_max, int base_guide, double[:, :, ::1] rec, double[:, :, ::1] world,
                i64[:, :, ::1] res,
                const double[:, :, ::1] y=None, const double[:, :, ::1] dz_points=None, double dz_dist=-1.0,
                bint neighbour_zone=False, double[:, :, ::1] uvd=None, const i64[::1] row_seg=None,
                i64[:, ::1] level_ref=None, Py_ssize_t first=0):
    """The recurrence of spec 4.3 for the strands ``strands_to_code`` (indices into ``[S]``; best
    grouped by card, whose triangles then stay in cache) of ``n`` points, into ``rec`` (scaled card
    coordinates ``[S, n, 3]``) and ``world`` (their world points). Decoding into ``uvd`` (float64
    ``[S, n, 3]``, given): ``rec`` and ``world`` are the scratch of the last ``SCRATCH_STRANDS`` strands
    (``[SCRATCH_STRANDS, n, 3]``: a strand's and those before it that its base samples may follow), and
    each strand's card coordinates ``rec / scale`` go to ``uvd``; returns how many of them float32
    cannot hold (beyond its range, or NaN: a corrupt file). Otherwise returns 0.

    With ``base_guide`` (1 to 3) a strand whose card neighbour came before it in ``strands_to_code``
    predicts its base samples from the neighbour's: its root from the neighbour's root, each later one
    by the neighbour's step in world space (with 2, times the ratio of the two strands' previous
    steps; with 3, after the first, the step of the most alike of the ``GUIDE_CANDIDATES`` strands
    before it on the card, :func:`unlikeness`), carried onto the card by the searched Newton steps
    (spec 4.3). ``strands_to_code`` must then list every card's strands in file order, whole.

    Levels: ``level_start [L + 1]`` delimits rows of ``idx [R]`` (the new indices), ``nb [R, W]`` and
    ``wt [R, W]`` (their interpolation neighbours and weights, summed left to right over the first
    ``level_taps[l]`` columns of level ``l``; the rest are padding). A refinement residual's steps on
    u and v stretch with the card's local scale up to ``stretch_max`` times (:func:`residual_steps`),
    and so do a guided base sample's. Decoding (``y`` None) reads the residuals
    ``res [S, len(base) + R, 3]`` (base samples, then the levels' rows); encoding writes them from ``y``
    (``[S, n, 3]``), leaving a refinement residual at zero where the prediction alone maps within
    ``dz_dist`` of ``dz_points`` (``dz_dist < 0``: no dead zone). With ``neighbour_zone`` a sample
    first takes the residual of its card neighbour (the strand coded before it, same card: its
    stored difference is then zero) where that too maps within ``dz_dist``: ``strands_to_code`` must
    then list a card's strands in file order, each after its neighbour.

    With ``row_seg`` (per level row, the base segment ``k`` it lies in, ``base[k] < idx < base[k + 1]``:
    ``level_guide``) each base segment of a strand with a card neighbour has a reference, the most alike
    of the strands before it (:func:`unlikeness`): decoding adds the reference's residuals to that
    segment's level rows (stored as differences); encoding writes the references' strand indices to
    ``level_ref [S, len(base) - 1]`` (-1: none; the caller takes the differences), and the neighbour
    zone tries the reference's residual instead of the neighbour's.

    Encoding, the strands before position ``first`` of ``strands_to_code`` are coded already (their
    ``rec``, ``world`` and ``res`` as the writer left them, before the level differences): the strands
    after them follow them as if coded in one run."""
    cdef Py_ssize_t t, s, j, li, row, kk, i, ch
    cdef Py_ssize_t strands = strands_to_code.shape[0], nbase = base.shape[0], levels = level_start.shape[0] - 1
    cdef int encode = y is not None, dead_zone = encode and dz_points is not None and dz_dist >= 0
    cdef int scratch = uvd is not None
    cdef Py_ssize_t unrepresentable = 0, npts = rec.shape[1]
    cdef double v
    cdef double pred[3]
    cdef double goal[3]
    cdef double f[3]
    cdef double jac[9]
    cdef double bf[3]
    cdef double w, ratio, rho, dist2 = dz_dist * dz_dist
    cdef const double* fr
    cdef const double* sc
    cdef double* R
    cdef double* W
    cdef double* RN
    cdef double* WN
    cdef double* RM
    cdef double* WM
    cdef const double* Y = NULL
    cdef const double* Z = NULL
    cdef i64* BR
    cdef i64* LR
    cdef i64* NB = NULL
    cdef i64 zero[3]
    cdef i64 card, a, b, c, m
    cdef int level_guide = row_seg is not None
    cdef i64* segref = NULL
    zero[0] = 0
    zero[1] = 0
    zero[2] = 0
    if strands == 0:
        return 0
    check_cards(strand_card, frames.shape[0], segments)
    shape = (strand_card.shape[0], rec.shape[1], 3)
    own = (SCRATCH_STRANDS,) + shape[1:] if scratch else shape  # the shape of rec and world
    if (frames.shape[1] != 18 or tuple(scale.shape)[:2] != shape[::2] or tuple(rec.shape)[:3] != own
            or tuple(world.shape)[:3] != own or tuple(res.shape)[:3] != (shape[0], nbase + idx.shape[0], 3)
            or (scratch and (encode or tuple(uvd.shape)[:3] != shape))
            or (y is not None and tuple(y.shape)[:3] != shape)
            or (dz_points is not None and tuple(dz_points.shape)[:3] != shape)
            or nb.shape[0] != idx.shape[0] or wt.shape[0] != idx.shape[0] or nb.shape[1] != wt.shape[1]
            or level_taps.shape[0] != levels or level_start[levels] != idx.shape[0]):
        raise ValueError("run_strands: mismatched shapes")
    for t in range(strands):
        if strands_to_code[t] < 0 or strands_to_code[t] >= shape[0]:
            raise ValueError("run_strands: a strand index is out of range")
    if not stretch_max >= 1.0:
        raise ValueError("run_strands: stretch_max must be at least 1")
    if first < 0 or first > strands or (first > 0 and not encode):
        raise ValueError("run_strands: first must lie in [0, strands], and be 0 decoding")
    for li in range(levels):
        if level_taps[li] < 0 or level_taps[li] > nb.shape[1]:
            raise ValueError("run_strands: a level's interpolation width exceeds its neighbour columns")
    if level_guide and (row_seg.shape[0] != idx.shape[0] or (level_ref is not None and (
            level_ref.shape[0] != shape[0] or level_ref.shape[1] != max(nbase - 1, 0)))):
        raise ValueError("run_strands: mismatched shapes")
    if level_guide:
        for row in range(idx.shape[0]):
            if row_seg[row] < 0 or row_seg[row] >= nbase - 1:
                raise ValueError("run_strands: a row's base segment is out of range")
    segref = <i64*> calloc(max(nbase, 1), sizeof(i64))
    if segref == NULL:
        raise MemoryError()
    fr = &frames[0, 0]
    with nogil:
        for t in range(first, strands):
            s = strands_to_code[t]
            card = strand_card[s]
            sc = &scale[s, 0]
            R = &rec[scratch_row(t, strands_to_code, scratch), 0, 0]
            W = &world[scratch_row(t, strands_to_code, scratch), 0, 0]
            RN = NULL  # with base_guide, the neighbour's reconstruction (spec 4.3)
            if base_guide > 0 and t > 0 and strand_card[strands_to_code[t - 1]] == card:
                RN = &rec[scratch_row(t - 1, strands_to_code, scratch), 0, 0]
                WN = &world[scratch_row(t - 1, strands_to_code, scratch), 0, 0]
            BR = &res[s, 0, 0]
            LR = BR + 3 * nbase
            NB = NULL  # encoding: the residuals of this strand's neighbour (spec 4.3), when coded already
            if encode:
                Y = &y[s, 0, 0]
                if dead_zone:
                    Z = &dz_points[s, 0, 0]
                    if neighbour_zone and t > 0 and strand_card[strands_to_code[t - 1]] == card:
                        NB = &res[strands_to_code[t - 1], 0, 0]
            for j in range(nbase):
                c = base[j]
                bf[0] = 1.0
                bf[1] = 1.0
                bf[2] = 1.0
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
                    residual_steps(jac, sc, stretch_max, bf)
                else:  # the strand's own base samples, per channel (spec 4.1)
                    for ch in range(3):
                        if j == 0:
                            pred[ch] = 0.0
                        elif j == 1 or base_order[ch] == 1:
                            pred[ch] = R[3 * base[j - 1] + ch]
                        else:
                            a = base[j - 2]
                            b = base[j - 1]
                            ratio = <double> (c - b) / <double> (b - a)
                            pred[ch] = R[3 * b + ch] + (R[3 * b + ch] - R[3 * a + ch]) * ratio
                if encode:
                    for ch in range(3):
                        BR[3 * j + ch] = <i64> rint((Y[3 * c + ch] - pred[ch]) / bf[ch])
                if dead_zone:
                    nearest(fr, segments, card, pred, bf, sc, Z + 3 * c, dist2, BR + 3 * j)
                if NB != NULL and fits(fr, segments, card, pred, NB + 3 * j, bf, sc, Z + 3 * c, dist2):
                    for ch in range(3):  # the neighbour's residual will do: its difference is zero
                        BR[3 * j + ch] = NB[3 * j + ch]
                for ch in range(3):
                    R[3 * c + ch] = pred[ch] + BR[3 * j + ch] * bf[ch]
                to_world(fr, segments, card, R + 3 * c, sc, W + 3 * c)
            if level_guide:  # per base segment, the most alike strand before it on the card
                for kk in range(nbase - 1):
                    segref[kk] = -1
                    if t > 0 and strand_card[strands_to_code[t - 1]] == card:
                        segref[kk] = strands_to_code[most_alike(t, strands_to_code, strand_card, world, scratch, W,
                                                                &base[0], max(kk - 1, 0), min(kk + 1, nbase - 2),
                                                                kk + 1)]
                    if level_ref is not None:
                        level_ref[s, kk] = segref[kk]
            for li in range(levels):
                for row in range(level_start[li], level_start[li + 1]):
                    i = idx[row]
                    for ch in range(3):
                        pred[ch] = 0.0
                        goal[ch] = 0.0
                    for kk in range(level_taps[li]):
                        w = wt[row, kk]
                        j = 3 * nb[row, kk]
                        for ch in range(3):
                            pred[ch] = pred[ch] + R[j + ch] * w
                            goal[ch] = goal[ch] + W[j + ch] * w
                    newton(fr, segments, card, sc, goal, newton_steps, newton_halvings, pred, jac)
                    residual_steps(jac, sc, stretch_max, f)
                    m = segref[row_seg[row]] if level_guide else -1
                    if level_guide and not encode and m >= 0:  # stored as the difference from m's
                        for ch in range(3):
                            LR[3 * row + ch] = <i64> (<uint64_t> LR[3 * row + ch]
                                                      + <uint64_t> res[m, nbase + row, ch])
                    if level_guide and dead_zone and neighbour_zone:
                        NB = &res[m, 0, 0] if m >= 0 else NULL
                    if encode:
                        for ch in range(3):
                            LR[3 * row + ch] = <i64> rint((Y[3 * i + ch] - pred[ch]) / f[ch])
                        if dead_zone:
                            nearest(fr, segments, card, pred, f, sc, Z + 3 * i, dist2, LR + 3 * row)
                        if NB != NULL and fits(fr, segments, card, pred, NB + 3 * (nbase + row), f, sc,
                                               Z + 3 * i, dist2):
                            for ch in range(3):  # the neighbour's residual will do: its difference is zero
                                LR[3 * row + ch] = NB[3 * (nbase + row) + ch]
                        elif dead_zone and fits(fr, segments, card, pred, zero, f, sc, Z + 3 * i, dist2):
                            LR[3 * row] = 0
                            LR[3 * row + 1] = 0
                            LR[3 * row + 2] = 0
                    for ch in range(3):
                        R[3 * i + ch] = pred[ch] + LR[3 * row + ch] * f[ch]
                    if encode or li + 1 < levels:  # a decoder predicts nothing from the last level
                        to_world(fr, segments, card, R + 3 * i, sc, W + 3 * i)
            if scratch:
                for i in range(npts):
                    for ch in range(3):
                        v = R[3 * i + ch] / sc[ch]
                        uvd[s, i, ch] = v
                        if not (fabs(v) <= FLT_MAX):
                            unrepresentable += 1
    free(segref)
    return unrepresentable


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


cdef enum:  # rans.py, residual_coder.py
    DIRECT = 16
    ALPHABET = 76
    PROB_BITS = 12
    LOW = 65536
    PREV_CLASSES = 8
    OTHER_CLASSES = 4
    CONTEXTS = 32

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
