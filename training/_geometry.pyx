# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled twin of :meth:`training.model.CardGeometry.points` followed by
:func:`training.model.segment_gaussians`: strand points on their cards (triangle, barycentrics,
the interpolated normal and the displacement along it) and one Gaussian per segment, forward and
backward, one strand per iteration on every core (OpenMP).

The torch functions stay the definition (and run on CUDA); this kernel computes the same values
in double precision from the same float32 inputs, taking the discrete decisions (segment,
triangle) in float32 as torch does, and writes float32.
"""

from cython.parallel import prange

from libc.math cimport floor, sqrt
from libc.stdint cimport int64_t
from libc.stdlib cimport free, malloc

cdef double LENGTH_SQ_MIN = 1e-30  # as segment_gaussians' clamp_min
cdef double NORMAL_MIN = 1e-30  # as points' clamp_min
cdef double W_MIN = 1e-12  # as segment_gaussians: a segment pointing along -z gets the fixed quaternion


cdef struct OnCard:  # one point's card lookup, what the backward pass needs again
    int64_t tri
    int upper
    double bary[3]
    double nrm_len


cdef void locate(const float* uv, float delta, int64_t card, int segments, const float* vertex_data,
                 const int64_t* triangles, OnCard* c, double* point, double* unit) noexcept nogil:
    """Point ``point[3]`` and unit normal ``unit[3]`` of card coordinates (u, v, delta)."""
    cdef float s = uv[0] * <float>segments
    cdef float k = <float>floor(s)
    cdef float f, v = uv[1]
    cdef double pos[3]
    cdef double nrm[3]
    cdef const float* corner
    cdef int i, j
    if k < 0:
        k = 0
    if k > segments - 1:
        k = segments - 1
    f = s - k
    c.upper = (f + v) > 1
    if c.upper:
        c.bary[0] = 1.0 - <double>f
        c.bary[1] = <double>f + <double>v - 1.0
        c.bary[2] = 1.0 - <double>v
    else:
        c.bary[0] = 1.0 - <double>f - <double>v
        c.bary[1] = <double>v
        c.bary[2] = <double>f
    c.tri = card * 2 * segments + 2 * <int64_t>k + c.upper
    for j in range(3):
        pos[j] = 0.0
        nrm[j] = 0.0
    for i in range(3):
        corner = vertex_data + 6 * triangles[3 * c.tri + i]
        for j in range(3):
            pos[j] += c.bary[i] * corner[j]
            nrm[j] += c.bary[i] * corner[3 + j]
    c.nrm_len = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
    if c.nrm_len < NORMAL_MIN:
        c.nrm_len = NORMAL_MIN
    for j in range(3):
        unit[j] = nrm[j] / c.nrm_len
        point[j] = pos[j] + delta * unit[j]


cdef void segment_frame(const double* p0, const double* p1, double* seg, double* length, double* d, double* qraw,
                        double* qlen, int* zero_len, int* flipped) noexcept nogil:
    """Direction ``d``, length and unnormalised quaternion (w, x, y, z) of a segment."""
    cdef int j
    for j in range(3):
        seg[j] = p1[j] - p0[j]
    zero_len[0] = seg[0] == 0 and seg[1] == 0 and seg[2] == 0
    cdef double ss = seg[0] * seg[0] + seg[1] * seg[1] + seg[2] * seg[2]
    length[0] = sqrt(ss if ss > LENGTH_SQ_MIN else LENGTH_SQ_MIN)
    if zero_len[0]:
        d[0] = 0.0
        d[1] = 0.0
        d[2] = 1.0
    else:
        for j in range(3):
            d[j] = seg[j] / length[0]
    qraw[0] = 1.0 + d[2]
    qraw[1] = -d[1]
    qraw[2] = d[0]
    qraw[3] = 0.0
    flipped[0] = qraw[0] < W_MIN
    if flipped[0]:
        qraw[0] = 0.0
        qraw[1] = 1.0
        qraw[2] = 0.0
    qlen[0] = sqrt(qraw[0] * qraw[0] + qraw[1] * qraw[1] + qraw[2] * qraw[2] + qraw[3] * qraw[3])


cdef void forward_strand(const float* uv, const float* delta, int n_points, int64_t card, int segments,
                         const float* vertex_data, const int64_t* triangles, float thickness, float* means,
                         float* quats, float* scales) noexcept nogil:
    cdef OnCard c
    cdef double seg[3]
    cdef double d[3]
    cdef double q[4]
    cdef double unit[3]
    cdef double length, qlen
    cdef int zero_len, flipped, p, j
    cdef double* pts = <double*>malloc(3 * n_points * sizeof(double))
    for p in range(n_points):
        locate(uv + 2 * p, delta[p], card, segments, vertex_data, triangles, &c, pts + 3 * p, unit)
    for p in range(n_points - 1):
        segment_frame(pts + 3 * p, pts + 3 * p + 3, seg, &length, d, q, &qlen, &zero_len, &flipped)
        for j in range(3):
            means[3 * p + j] = <float>((pts[3 * p + j] + pts[3 * p + 3 + j]) / 2)
        for j in range(4):
            quats[4 * p + j] = <float>(q[j] / qlen)
        scales[3 * p] = thickness
        scales[3 * p + 1] = thickness
        scales[3 * p + 2] = 0.0 if zero_len else <float>(length / 2)
    free(pts)


def forward(const float[:, :, ::1] uv, const float[:, ::1] delta, const float[:, ::1] vertex_data,
            const int64_t[:, ::1] triangles, const int64_t[::1] strand_card, int segments, float thickness,
            float[:, ::1] means, float[:, ::1] quats, float[:, ::1] scales):
    """Means ``[S*(P-1), 3]``, quaternions (w, x, y, z) and scales of the strands' segments."""
    cdef Py_ssize_t n_strands = uv.shape[0], s
    cdef int n_points = uv.shape[1]
    if n_strands == 0 or n_points < 2:
        return
    for s in prange(n_strands, nogil=True, schedule="static"):
        forward_strand(&uv[s, 0, 0], &delta[s, 0], n_points, strand_card[s], segments, &vertex_data[0, 0],
                       &triangles[0, 0], thickness, &means[s * (n_points - 1), 0], &quats[s * (n_points - 1), 0],
                       &scales[s * (n_points - 1), 0])


cdef void backward_strand(const float* uv, const float* delta, int n_points, int64_t card, int segments,
                          const float* vertex_data, const int64_t* triangles, const float* grad_means,
                          const float* grad_quats, const float* grad_scales, float* grad_uv,
                          float* grad_delta) noexcept nogil:
    cdef OnCard* cs = <OnCard*>malloc(n_points * sizeof(OnCard))
    cdef double* pts = <double*>malloc(3 * n_points * sizeof(double))
    cdef double* units = <double*>malloc(3 * n_points * sizeof(double))
    cdef double* gp = <double*>malloc(3 * n_points * sizeof(double))  # dL/dpoint
    cdef double seg[3]
    cdef double d[3]
    cdef double q[4]
    cdef double gq[4]
    cdef double gd[3]
    cdef double gn[3]
    cdef double db[3]
    cdef const float* corner
    cdef double length, qlen, dot, glen, gf, gv, gdelta, nd
    cdef int zero_len, flipped, p, i, j
    for p in range(n_points):
        locate(uv + 2 * p, delta[p], card, segments, vertex_data, triangles, cs + p, pts + 3 * p, units + 3 * p)
        for j in range(3):
            gp[3 * p + j] = 0.0
    for p in range(n_points - 1):
        segment_frame(pts + 3 * p, pts + 3 * p + 3, seg, &length, d, q, &qlen, &zero_len, &flipped)
        for j in range(3):  # means = (p0 + p1) / 2
            gp[3 * p + j] += 0.5 * grad_means[3 * p + j]
            gp[3 * p + 3 + j] += 0.5 * grad_means[3 * p + j]
        if zero_len:  # fixed direction, zero length: nothing flows back
            continue
        for j in range(3):
            gd[j] = 0.0
        if not flipped:  # q = qraw / |qraw|, qraw = (1 + d_z, -d_y, d_x, 0)
            dot = 0.0  # unit q . dL/dq
            for j in range(4):
                dot = dot + q[j] / qlen * grad_quats[4 * p + j]
            for j in range(4):
                gq[j] = (grad_quats[4 * p + j] - q[j] / qlen * dot) / qlen
            gd[2] += gq[0]
            gd[1] -= gq[1]
            gd[0] += gq[2]
        glen = 0.5 * grad_scales[3 * p + 2]
        if length * length <= LENGTH_SQ_MIN:  # the clamp passes no gradient to the length
            glen = 0.0
        dot = d[0] * gd[0] + d[1] * gd[1] + d[2] * gd[2]
        for j in range(3):  # d = seg / length, length = |seg|
            nd = (gd[j] - d[j] * dot) / length + d[j] * glen
            gp[3 * p + 3 + j] += nd
            gp[3 * p + j] -= nd
    for p in range(n_points):  # point = sum_i b_i P_i + delta * n / |n|, n = sum_i b_i N_i
        gdelta = gp[3 * p] * units[3 * p] + gp[3 * p + 1] * units[3 * p + 1] + gp[3 * p + 2] * units[3 * p + 2]
        grad_delta[p] = <float>gdelta
        for j in range(3):
            gn[j] = delta[p] * (gp[3 * p + j] - units[3 * p + j] * gdelta) / cs[p].nrm_len
        for i in range(3):
            corner = vertex_data + 6 * triangles[3 * cs[p].tri + i]
            db[i] = 0.0
            for j in range(3):
                db[i] += corner[j] * gp[3 * p + j] + corner[3 + j] * gn[j]
        if cs[p].upper:  # (1 - f, f + v - 1, 1 - v)
            gf = db[1] - db[0]
            gv = db[1] - db[2]
        else:  # (1 - f - v, v, f)
            gf = db[2] - db[0]
            gv = db[1] - db[0]
        grad_uv[2 * p] = <float>(gf * segments)
        grad_uv[2 * p + 1] = <float>gv
    free(cs)
    free(pts)
    free(units)
    free(gp)


def backward(const float[:, :, ::1] uv, const float[:, ::1] delta, const float[:, ::1] vertex_data,
             const int64_t[:, ::1] triangles, const int64_t[::1] strand_card, int segments,
             const float[:, ::1] grad_means, const float[:, ::1] grad_quats, const float[:, ::1] grad_scales,
             float[:, :, ::1] grad_uv, float[:, ::1] grad_delta):
    """Gradients of (u, v) and delta from those of the means, quaternions and scales."""
    cdef Py_ssize_t n_strands = uv.shape[0], s
    cdef int n_points = uv.shape[1]
    cdef Py_ssize_t first
    if n_strands == 0 or n_points < 2:
        return
    for s in prange(n_strands, nogil=True, schedule="static"):
        first = s * (n_points - 1)
        backward_strand(&uv[s, 0, 0], &delta[s, 0], n_points, strand_card[s], segments, &vertex_data[0, 0],
                        &triangles[0, 0], &grad_means[first, 0], &grad_quats[first, 0], &grad_scales[first, 0],
                        &grad_uv[s, 0, 0], &grad_delta[s, 0])
