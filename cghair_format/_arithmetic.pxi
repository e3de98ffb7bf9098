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

cdef struct Plan:  # spec 4.3's prediction plan (strand_coder.Recurrence) as the recurrence reads it
    const i64* base  # [nbase] the base samples, ...
    Py_ssize_t nbase
    const i64* base_order  # [3] ... their predictor order per channel u, v, delta
    const i64* level_start  # [levels + 1] the rows of each level, ...
    Py_ssize_t levels
    const i64* level_taps  # [levels] ... the columns of nb and wt each uses
    const i64* idx  # [rows] the sample each row predicts, ...
    const i64* nb  # [rows, width] ... from these samples (interpolation neighbours) ...
    const double* wt  # [rows, width] ... with these weights
    Py_ssize_t width
    const i64* row_seg  # [rows] each row's base segment (level_guide), or NULL: no level guide
    int newton_steps
    int newton_halvings
    double stretch_max
    int base_guide


cdef struct Coding:  # the strands being coded, on their cards, and what is reconstructed of them
    const i64* order  # [count] the strands (indices into [S]) in coding order: strands_to_code
    Py_ssize_t count
    const i64* card  # [S] each strand's card ...
    const double* scale  # [S, 3] ... and scale g (spec 4.3)
    const double* frames  # the cards' triangles (geometry.CardMap)
    int segments
    double* rec  # [rows, points, 3] scaled card coordinates ...
    double* world  # [rows, points, 3] ... and world points of the strands coded
    Py_ssize_t points
    bint scratch  # rows: SCRATCH_STRANDS in turn (decoding), else one per strand


cdef struct Strand:  # the strand at position t of the coding order, being coded
    Py_ssize_t t
    i64 card
    const double* sc  # its scale
    double* R  # its scaled card coordinates ...
    double* W  # ... and world points so far
    const double* RN  # its card neighbour's (the strand before it on its card): NULL with base_guide 0 ...
    const double* WN  # ... or without a card neighbour


cdef class PlanView:
    """A plan's arrays (:class:`strand_coder.Recurrence`), checked (the kernels read them unchecked),
    held for one kernel call, and the :c:type:`Plan` that points into them."""
    cdef const i64[::1] base, base_order, level_start, level_taps, idx, row_seg
    cdef const i64[:, ::1] nb
    cdef const double[:, ::1] wt
    cdef Plan c

    def __cinit__(self, plan):
        cdef Py_ssize_t li, row, levels
        self.base, self.base_order, self.level_start = plan.base, plan.base_order, plan.level_start
        self.level_taps, self.idx, self.nb, self.wt = plan.level_taps, plan.idx, plan.nb, plan.wt
        self.row_seg = plan.row_seg
        levels = self.level_start.shape[0] - 1
        if (self.base_order.shape[0] != 3 or levels < 0 or self.nb.shape[0] != self.idx.shape[0]
                or self.wt.shape[0] != self.idx.shape[0] or self.nb.shape[1] != self.wt.shape[1]
                or self.level_taps.shape[0] != levels or self.level_start[levels] != self.idx.shape[0]
                or (self.row_seg is not None and self.row_seg.shape[0] != self.idx.shape[0])):
            raise ValueError("strand recurrence: mismatched shapes")
        if not plan.stretch_max >= 1.0:
            raise ValueError("strand recurrence: stretch_max must be at least 1")
        for li in range(levels):
            if self.level_taps[li] < 0 or self.level_taps[li] > self.nb.shape[1]:
                raise ValueError("strand recurrence: a level's interpolation width exceeds its neighbour columns")
        if self.row_seg is not None:
            for row in range(self.idx.shape[0]):
                if self.row_seg[row] < 0 or self.row_seg[row] >= self.base.shape[0] - 1:
                    raise ValueError("strand recurrence: a row's base segment is out of range")
        self.c.base = &self.base[0]
        self.c.nbase = self.base.shape[0]
        self.c.base_order = &self.base_order[0]
        self.c.level_start = &self.level_start[0]
        self.c.levels = levels
        self.c.level_taps = &self.level_taps[0]
        self.c.idx = &self.idx[0]
        self.c.nb = &self.nb[0, 0]
        self.c.wt = &self.wt[0, 0]
        self.c.width = self.nb.shape[1]
        self.c.row_seg = NULL
        if self.row_seg is not None:
            self.c.row_seg = &self.row_seg[0]
        self.c.newton_steps = plan.newton_steps
        self.c.newton_halvings = plan.newton_halvings
        self.c.stretch_max = plan.stretch_max
        self.c.base_guide = plan.base_guide


cdef class CodingView:
    """The strands ``strands_to_code`` on the cards of ``layout`` (:class:`strand_coder.Layout`: the
    cards' frames and segments, each strand's card and scale) with the reconstruction's rows ``rec``
    and ``world`` (``scratch``: SCRATCH_STRANDS of them, else one per strand), checked and held for
    one kernel call, and the :c:type:`Coding` that points into them."""
    cdef const i64[::1] order, card
    cdef const double[:, ::1] frames, scale
    cdef double[:, :, ::1] rec, world
    cdef Coding c

    def __cinit__(self, layout, const i64[::1] strands_to_code, double[:, :, ::1] rec, double[:, :, ::1] world,
                  bint scratch):
        cdef Py_ssize_t t, strands
        self.frames, self.card, self.scale = layout.frames, layout.strand_card, layout.scale
        self.order, self.rec, self.world = strands_to_code, rec, world
        strands = self.card.shape[0]
        check_cards(self.card, self.frames.shape[0], layout.segments)
        shape = (SCRATCH_STRANDS if scratch else strands, rec.shape[1], 3)
        if (self.frames.shape[1] != 18 or self.scale.shape[0] != strands or self.scale.shape[1] != 3
                or tuple(rec.shape)[:3] != shape or tuple(world.shape)[:3] != shape):
            raise ValueError("strand recurrence: mismatched shapes")
        for t in range(strands_to_code.shape[0]):
            if strands_to_code[t] < 0 or strands_to_code[t] >= strands:
                raise ValueError("strand recurrence: a strand index is out of range")
        self.c.order = &self.order[0]  # (the pointers of empty arrays are never read)
        self.c.count = strands_to_code.shape[0]
        self.c.card = &self.card[0]
        self.c.scale = &self.scale[0, 0]
        self.c.frames = &self.frames[0, 0]
        self.c.segments = layout.segments
        self.c.rec = &self.rec[0, 0, 0]
        self.c.world = &self.world[0, 0, 0]
        self.c.points = rec.shape[1]
        self.c.scratch = scratch

    def check_residuals(self, PlanView plan, const i64[:, :, ::1] res):
        """``res`` must hold every strand's residuals under ``plan``: ``[S, nbase + rows, 3]``."""
        if tuple(res.shape)[:3] != (self.card.shape[0], plan.c.nbase + plan.idx.shape[0], 3):
            raise ValueError("strand recurrence: mismatched shapes")


cdef inline double* strand_row(double* rows, const Coding* co, Py_ssize_t t) noexcept nogil:
    """The row of ``rows`` (``co.rec`` or ``co.world``) holding the strand at position ``t``: its own,
    or decoding, one of the scratch's SCRATCH_STRANDS in turn."""
    return rows + 3 * co.points * ((t % (CANDIDATES + 1)) if co.scratch else co.order[t])


cdef inline const double* card_neighbour(const Coding* co, Py_ssize_t t, double* rows) noexcept nogil:
    """The row of ``rows`` (``co.rec`` or ``co.world``) of the strand before position ``t`` when it lies
    on the same card (the card neighbour, spec 4.3.1), else NULL."""
    if t > 0 and co.card[co.order[t - 1]] == co.card[co.order[t]]:
        return strand_row(rows, co, t - 1)
    return NULL


cdef inline void start_strand(const Plan* plan, const Coding* co, Py_ssize_t t, Strand* st) noexcept nogil:
    """``st``: the strand at position ``t``, its rows and its card neighbour's."""
    cdef i64 s = co.order[t]
    st.t = t
    st.card = co.card[s]
    st.sc = co.scale + 3 * s
    st.R = strand_row(co.rec, co, t)
    st.W = strand_row(co.world, co, t)
    st.RN = card_neighbour(co, t, co.rec) if plan.base_guide > 0 else NULL
    st.WN = card_neighbour(co, t, co.world)


cdef inline Py_ssize_t most_alike(const Plan* plan, const Coding* co, const Strand* st, Py_ssize_t first,
                                  Py_ssize_t last, Py_ssize_t at) noexcept nogil:
    """Of the CANDIDATES strands before ``st`` on its card (the one at ``st.t - 1`` must be), the
    position of the most alike to it by :func:`unlikeness` over ``first, last, at``: the neighbour
    ``st.t - 1``, unless one farther back is less unlike (strictly: a tie, or NaN, keeps the nearer)."""
    cdef Py_ssize_t k, t = st.t, pick = st.t - 1
    cdef double d, best = unlikeness(st.W, strand_row(co.world, co, t - 1), plan.base, first, last, at, INFINITY)
    k = t - 2
    while k >= 0 and k >= t - CANDIDATES and co.card[co.order[k]] == st.card:
        d = unlikeness(st.W, strand_row(co.world, co, k), plan.base, first, last, at, best)
        if d < best:
            best = d
            pick = k
        k -= 1
    return pick


cdef inline void predict_base(const Plan* plan, const Coding* co, const Strand* st, Py_ssize_t j, double* pred,
                              double* f) noexcept nogil:
    """Base sample ``j``'s prediction ``pred`` and residual steps ``f`` (spec 4.3) for the strand ``st``
    with scaled card coordinates ``st.R`` and world points ``st.W`` so far. With a card neighbour
    (``st.RN``, ``st.WN`` not NULL; ``base_guide`` > 0): its root, then its step (with 2, scaled as the
    previous steps compare; with 3, after the first, the step of the most alike strand before it), in
    world space, carried onto the card by the searched Newton steps. Else the strand's own base
    samples, per channel (spec 4.1)."""
    cdef const i64* base = plan.base
    cdef const double* R = st.R
    cdef const double* W = st.W
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
    if st.RN != NULL and j == 0:  # the neighbour's root
        for ch in range(3):
            pred[ch] = st.RN[3 * c + ch]
    elif st.RN != NULL:  # the neighbour's step, in world space, onto the card
        b = base[j - 1]
        rho = 1.0
        if plan.base_guide == 2 and j > 1:  # scaled as the previous steps compare
            a = base[j - 2]
            rho = step_ratio(W + 3 * a, W + 3 * b, st.WN + 3 * a, st.WN + 3 * b)
        RM = st.RN
        WM = st.WN
        if plan.base_guide == 3 and j > 1:  # the most alike strand of those before it
            a = most_alike(plan, co, st, max(j - 3, 0), j - 2, j - 1)
            RM = strand_row(co.rec, co, a)
            WM = strand_row(co.world, co, a)
        for ch in range(3):
            pred[ch] = R[3 * b + ch] + rho * (RM[3 * c + ch] - RM[3 * b + ch])
            goal[ch] = W[3 * b + ch] + rho * (WM[3 * c + ch] - WM[3 * b + ch])
        newton(co.frames, co.segments, st.card, st.sc, goal, plan.newton_steps, plan.newton_halvings, pred, jac)
        residual_steps(jac, st.sc, plan.stretch_max, f)
    else:  # the strand's own base samples, per channel (spec 4.1)
        for ch in range(3):
            if j == 0:
                pred[ch] = 0.0
            elif j == 1 or plan.base_order[ch] == 1:
                pred[ch] = R[3 * base[j - 1] + ch]
            else:
                a = base[j - 2]
                b = base[j - 1]
                rho = <double> (c - b) / <double> (b - a)
                pred[ch] = R[3 * b + ch] + (R[3 * b + ch] - R[3 * a + ch]) * rho


cdef inline void segment_references(const Plan* plan, const Coding* co, const Strand* st,
                                    i64* segref) noexcept nogil:
    """``level_guide`` (spec 4.3.1): per base segment ``k``, ``segref[k]``, the strand whose refinement
    residuals the segment's are differences from: the most alike of those before ``st`` on its card
    (-1 without a card neighbour)."""
    cdef Py_ssize_t k, nbase = plan.nbase
    for k in range(nbase - 1):
        segref[k] = -1
        if st.WN != NULL:
            segref[k] = co.order[most_alike(plan, co, st, max(k - 1, 0), min(k + 1, nbase - 2), k + 1)]


cdef inline void predict_level(const Plan* plan, const Coding* co, const Strand* st, Py_ssize_t li,
                               Py_ssize_t row, double* pred, double* f) noexcept nogil:
    """Row ``row`` (of level ``li``)'s prediction ``pred`` and residual steps ``f`` (spec 4.3): the
    Lagrange interpolation (the level's first ``level_taps[li]`` columns of ``nb`` and ``wt``, left to
    right) of the strand's scaled card coordinates and of its world points, the second carried onto
    the card by the searched Newton steps from the first."""
    cdef double goal[3]
    cdef double jac[9]
    cdef double w
    cdef Py_ssize_t k, j, taps = plan.level_taps[li]
    cdef int ch
    for ch in range(3):
        pred[ch] = 0.0
        goal[ch] = 0.0
    for k in range(taps):
        w = plan.wt[row * plan.width + k]
        j = 3 * plan.nb[row * plan.width + k]
        for ch in range(3):
            pred[ch] = pred[ch] + st.R[j + ch] * w
            goal[ch] = goal[ch] + st.W[j + ch] * w
    newton(co.frames, co.segments, st.card, st.sc, goal, plan.newton_steps, plan.newton_halvings, pred, jac)
    residual_steps(jac, st.sc, plan.stretch_max, f)


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
