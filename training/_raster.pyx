# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled CPU splatting kernels of :mod:`training.native_splat` (spec/rendering.md), forward and
backward, run on every core through OpenMP with the GIL released.

- :func:`project`: per Gaussian, the EWA projection and the tiles its footprint touches.
- :func:`bin_tiles`: the Gaussians in depth order (stable) and per 16 x 16 tile the list of
  those it touches, front to back.
- :func:`rasterize`: per tile, front-to-back compositing with early termination (SH colours
  computed only for the Gaussians that contribute); keeps per pixel the final transmittance and
  the last contribution, all the backward pass needs.
- :func:`contributors`: the same compositing on opacities alone, marking the Gaussians that
  contribute, so that SH need be computed for those only.
- :func:`rasterize_backward`: per tile, each pixel's contributions walked back to front;
  per (Gaussian, tile) gradients, then summed per Gaussian without races.
- :func:`project_backward`: per Gaussian, gradients through SH and the projection.
"""

from cython.parallel import prange

from libc.math cimport ceil, expf, floor, isfinite, log, sqrt
from libc.stdint cimport int32_t, int64_t, uint8_t, uint32_t
from libc.stdlib cimport free, malloc

cpdef enum:  # read by training.native_splat as module attributes: stated here alone
    TILE = 16  # tile side in pixels
    NF = 10  # per-Gaussian features the rasterizer reads, see project()

cdef enum:
    AHEAD = 16  # entries prefetched ahead: the features of a tile's list are scattered in memory

cdef extern from *:
    """
    #if defined(__GNUC__)
    #define PREFETCH(p) __builtin_prefetch(p)
    #else
    #define PREFETCH(p) ((void)0)
    #endif
    """
    void PREFETCH(const void* p) noexcept nogil

cdef double NEAR_PLANE = 0.01
cdef double DILATION = 0.3
cdef float ALPHA_MAX = 0.99
cdef float ALPHA_MIN = 1.0 / 255.0
cdef double T_MIN = 1e-4
cdef double SIGMA_SUPPORT = 3.0

cdef double C0 = 0.28209479177387814
cdef double C1 = 0.4886025119029199
cdef double C2[5]
C2[:] = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396]
cdef double C3[7]
C3[:] = [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435]


cdef inline double dmin(double a, double b) noexcept nogil:
    return a if a < b else b


cdef inline double dmax(double a, double b) noexcept nogil:
    return a if a > b else b


cdef inline int first_pixel(double lo, int first, int last) noexcept nogil:
    """The first pixel k with k + 0.5 >= lo, clamped to [first, last + 1]; NaN or beyond: last + 1."""
    cdef double v = ceil(lo - 0.5)
    if v < first:
        return first
    return <int>v if v <= last else last + 1  # NaN fails both tests


cdef inline int last_pixel(double hi, int first, int last) noexcept nogil:
    """The last pixel k with k + 0.5 <= hi, clamped to [first - 1, last]; NaN or before: first - 1."""
    cdef double v = floor(hi - 0.5)
    if v > last:
        return last
    return <int>v if v >= first else first - 1


cdef void sh_basis(int n, double x, double y, double z, double* b, double* bx, double* by,
                   double* bz) noexcept nogil:
    """The first ``n`` SH basis values at (x, y, z) and their partial derivatives
    (the polynomial of cghair_format.gaussians.sh_polynomial)."""
    cdef int k
    for k in range(n):
        bx[k] = 0.0
        by[k] = 0.0
        bz[k] = 0.0
    b[0] = C0
    if n < 4:
        return
    b[1] = -C1 * y
    by[1] = -C1
    b[2] = C1 * z
    bz[2] = C1
    b[3] = -C1 * x
    bx[3] = -C1
    if n < 9:
        return
    cdef double xx = x * x, yy = y * y, zz = z * z
    b[4] = C2[0] * x * y
    bx[4] = C2[0] * y
    by[4] = C2[0] * x
    b[5] = C2[1] * y * z
    by[5] = C2[1] * z
    bz[5] = C2[1] * y
    b[6] = C2[2] * (2 * zz - xx - yy)
    bx[6] = -2 * C2[2] * x
    by[6] = -2 * C2[2] * y
    bz[6] = 4 * C2[2] * z
    b[7] = C2[3] * x * z
    bx[7] = C2[3] * z
    bz[7] = C2[3] * x
    b[8] = C2[4] * (xx - yy)
    bx[8] = 2 * C2[4] * x
    by[8] = -2 * C2[4] * y
    if n < 16:
        return
    b[9] = C3[0] * y * (3 * xx - yy)
    bx[9] = C3[0] * 6 * x * y
    by[9] = C3[0] * (3 * xx - 3 * yy)
    b[10] = C3[1] * x * y * z
    bx[10] = C3[1] * y * z
    by[10] = C3[1] * x * z
    bz[10] = C3[1] * x * y
    b[11] = C3[2] * y * (4 * zz - xx - yy)
    bx[11] = -2 * C3[2] * x * y
    by[11] = C3[2] * (4 * zz - xx - 3 * yy)
    bz[11] = 8 * C3[2] * y * z
    b[12] = C3[3] * z * (2 * zz - 3 * xx - 3 * yy)
    bx[12] = -6 * C3[3] * x * z
    by[12] = -6 * C3[3] * y * z
    bz[12] = C3[3] * (6 * zz - 3 * xx - 3 * yy)
    b[13] = C3[4] * x * (4 * zz - xx - yy)
    bx[13] = C3[4] * (4 * zz - 3 * xx - yy)
    by[13] = -2 * C3[4] * x * y
    bz[13] = 8 * C3[4] * x * z
    b[14] = C3[5] * z * (xx - yy)
    bx[14] = 2 * C3[5] * x * z
    by[14] = -2 * C3[5] * y * z
    bz[14] = C3[5] * (xx - yy)
    b[15] = C3[6] * x * (xx - 3 * yy)
    bx[15] = C3[6] * (3 * xx - 3 * yy)
    by[15] = -6 * C3[6] * x * y


cdef void quat_rotmat(const float* q4, double* q, double* inv_norm, double* r) noexcept nogil:
    """Unit quaternion ``q`` of ``q4`` (w, x, y, z), 1 / its clamped norm, rotation matrix ``r``."""
    cdef double n = sqrt(<double>q4[0] * q4[0] + <double>q4[1] * q4[1] + <double>q4[2] * q4[2]
                         + <double>q4[3] * q4[3])
    n = dmax(n, 1e-12)
    inv_norm[0] = 1.0 / n
    cdef int k
    for k in range(4):
        q[k] = q4[k] / n
    cdef double w = q[0], x = q[1], y = q[2], z = q[3]
    r[0] = 1 - 2 * (y * y + z * z)
    r[1] = 2 * (x * y - w * z)
    r[2] = 2 * (x * z + w * y)
    r[3] = 2 * (x * y + w * z)
    r[4] = 1 - 2 * (x * x + z * z)
    r[5] = 2 * (y * z - w * x)
    r[6] = 2 * (x * z - w * y)
    r[7] = 2 * (y * z + w * x)
    r[8] = 1 - 2 * (x * x + y * y)


cdef inline double footprint_q(float opacity) noexcept nogil:
    """Bound on q = d^T Sigma2^-1 d inside which alpha can reach 1/255 (with the reference's margin)."""
    cdef double q = 2 * log(dmax(opacity / <double>ALPHA_MIN, 1e-30)) * (1 + 1e-6) + 1e-6
    return dmax(q, 0.0)


cdef void colour_of(const float* mean, const float* sh, int nc, const double* cam,
                    double* colour) noexcept nogil:
    """SH colour seen from the camera centre: ``max(0, sum_lm sh_lm Y_lm(dir) + 0.5)``."""
    cdef double d[3]
    cdef double b[16]
    cdef double bx[16]
    cdef double by[16]
    cdef double bz[16]
    cdef double nd, col
    cdef int k, ch
    for k in range(3):
        d[k] = mean[k] - cam[12 + k]
    nd = 1.0 / dmax(sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), 1e-12)
    sh_basis(nc, d[0] * nd, d[1] * nd, d[2] * nd, b, bx, by, bz)
    for ch in range(3):
        col = 0.0
        for k in range(nc):
            col += b[k] * sh[3 * k + ch]
        colour[ch] = dmax(col + 0.5, 0.0)


cdef struct Ewa:  # a Gaussian's EWA projection (ewa_rows), which the backward pass recomputes
    double q[4]  # the unit quaternion, ...
    double inv_n  # ... its inverse norm ...
    double r[9]  # ... and rotation matrix
    double jw0[3]  # the rows of J W ...
    double jw1[3]
    double a0[3]  # ... and of A = J W R_q S
    double a1[3]
    double ca  # the dilated 2D covariance (ca, cb; cb, cc)
    double cb
    double cc


cdef void ewa_rows(const float* quat, const float* scale, const double* cam, double x, double y, double iz,
                   Ewa* e) noexcept nogil:
    """The EWA projection ``e`` of a Gaussian at camera-space (x, y, 1 / iz)."""
    cdef double fx = cam[15], fy = cam[16], m
    cdef int k, j
    quat_rotmat(quat, e.q, &e.inv_n, e.r)
    for k in range(3):
        e.jw0[k] = fx * iz * cam[k] - fx * x * iz * iz * cam[6 + k]
        e.jw1[k] = fy * iz * cam[3 + k] - fy * y * iz * iz * cam[6 + k]
    for j in range(3):  # A = J W R_q S, by rows
        e.a0[j] = 0.0
        e.a1[j] = 0.0
        for k in range(3):
            m = e.r[3 * k + j] * scale[j]
            e.a0[j] += e.jw0[k] * m
            e.a1[j] += e.jw1[k] * m
    e.ca = e.a0[0] * e.a0[0] + e.a0[1] * e.a0[1] + e.a0[2] * e.a0[2] + DILATION
    e.cb = e.a0[0] * e.a1[0] + e.a0[1] * e.a1[1] + e.a0[2] * e.a1[2]
    e.cc = e.a1[0] * e.a1[0] + e.a1[1] * e.a1[1] + e.a1[2] * e.a1[2] + DILATION


cdef void project_one(const float* mean, const float* quat, const float* scale, float opacity,
                      const double* cam, int width, int height, float* f, int32_t* rect,
                      int64_t* ntiles) noexcept nogil:
    cdef double fx = cam[15], fy = cam[16], cx = cam[17], cy = cam[18]
    cdef double t[3]
    cdef Ewa e
    cdef double x, y, z, iz, ca, cb, cc, det, idet, mid, lam, rad, qmax, hx, hy, mx, my
    cdef int k, x0, x1, y0, y1
    for k in range(3):
        t[k] = cam[3 * k] * mean[0] + cam[3 * k + 1] * mean[1] + cam[3 * k + 2] * mean[2] + cam[9 + k]
    f[6] = <float>t[2]
    for k in range(4):
        rect[k] = 0
    ntiles[0] = 0
    if not (<float>t[2] > NEAR_PLANE):
        return
    x = t[0]
    y = t[1]
    z = t[2]
    iz = 1.0 / z
    ewa_rows(quat, scale, cam, x, y, iz, &e)
    ca, cb, cc = e.ca, e.cb, e.cc
    det = ca * cc - cb * cb
    idet = 1.0 / det
    f[2] = <float>(cc * idet)
    f[3] = <float>(-cb * idet)
    f[4] = <float>(ca * idet)
    f[5] = opacity
    mx = fx * x * iz + cx
    my = fy * y * iz + cy
    f[0] = <float>mx
    f[1] = <float>my
    mid = 0.5 * (ca + cc)
    lam = mid + sqrt(dmax(mid * mid - det, 0.0))
    rad = ceil(SIGMA_SUPPORT * sqrt(lam))
    qmax = footprint_q(opacity)
    hx = dmin(sqrt(qmax * ca), rad)
    hy = dmin(sqrt(qmax * cc), rad)
    f[7] = <float>qmax
    f[8] = <float>rad
    f[9] = <float>hy
    # pixels k with |k + 0.5 - m| <= h, clipped to the image, then their tiles
    x0 = first_pixel(mx - hx, 0, width - 1)
    x1 = last_pixel(mx + hx, 0, width - 1)
    y0 = first_pixel(my - hy, 0, height - 1)
    y1 = last_pixel(my + hy, 0, height - 1)
    if not (qmax > 0) or x0 > x1 or y0 > y1 or not (isfinite(f[2]) and isfinite(f[3]) and isfinite(f[4])):
        return  # off-screen, transparent, or not finite (NaN or infinite inputs)
    rect[0] = x0 // TILE
    rect[1] = y0 // TILE
    rect[2] = x1 // TILE + 1
    rect[3] = y1 // TILE + 1
    ntiles[0] = (rect[2] - rect[0]) * (rect[3] - rect[1])


def project(const float[:, ::1] means, const float[:, ::1] quats, const float[:, ::1] scales,
            const float[::1] opacities, const double[::1] cam, int width, int height, float[:, ::1] feat,
            int32_t[:, ::1] rect, int64_t[::1] ntiles):
    """Per Gaussian the features the rasterizer reads, ``feat [G, 10]``: screen centre (2), conic
    (3), opacity, camera depth, footprint bound q, radius, half-height of the footprint's rows; and
    the tile rectangle [x0, y0, x1, y1) its footprint touches (ntiles 0 when culled). Colours are
    computed later, only for the Gaussians that contribute. ``cam`` holds world-to-camera rotation
    (9, row-major), translation (3), camera centre (3), fx, fy, cx, cy."""
    cdef Py_ssize_t g
    for g in prange(means.shape[0], nogil=True, schedule="static"):
        project_one(&means[g, 0], &quats[g, 0], &scales[g, 0], opacities[g], &cam[0], width, height,
                    &feat[g, 0], &rect[g, 0], &ntiles[g])


cdef struct Item:  # a Gaussian and its sort key (the bits of its depth)
    uint32_t key
    int32_t g


def bin_tiles(const float[:, ::1] feat, const int32_t[:, ::1] rect, const int64_t[::1] ntiles,
              int tiles_x, int tiles_y, int64_t[::1] pair_start, int32_t[::1] tile_start,
              int32_t[::1] entries, int32_t[::1] entry_pair):
    """Sort the Gaussians with tiles by depth (stable radix sort of the float bits, so ties keep
    input order as the reference's stable argsort does), then list them per tile front to back.

    Fills ``pair_start[:G+1]`` (first (Gaussian, tile) pair of each Gaussian, in input order),
    ``tile_start[:tiles+1]`` (first entry of each tile), ``entries`` (the Gaussian of each entry,
    as long as the number of pairs) and ``entry_pair`` (its pair index); returns the number of
    Gaussians with tiles. Serial: a few passes over the arrays.
    """
    cdef Py_ssize_t n = feat.shape[0], g, i, v = 0, k
    cdef int tiles = tiles_x * tiles_y, pass_, shift, tx, ty
    cdef int64_t p, c
    cdef int64_t hist[2048]
    cdef Item* src = <Item*>malloc(max(n, 1) * sizeof(Item))
    cdef Item* dst = <Item*>malloc(max(n, 1) * sizeof(Item))
    cdef int64_t* cursor = <int64_t*>malloc((tiles + 1) * sizeof(int64_t))
    cdef Item* swap
    if src == NULL or dst == NULL or cursor == NULL:
        free(src)
        free(dst)
        free(cursor)
        raise MemoryError()
    with nogil:
        pair_start[0] = 0
        for k in range(tiles + 1):
            tile_start[k] = 0
        for g in range(n):
            pair_start[g + 1] = pair_start[g] + ntiles[g]
            if ntiles[g] > 0:
                src[v].key = (<const uint32_t*>&feat[g, 6])[0]
                src[v].g = <int32_t>g
                v += 1
                for ty in range(rect[g, 1], rect[g, 3]):
                    for tx in range(rect[g, 0], rect[g, 2]):
                        tile_start[ty * tiles_x + tx + 1] += 1
        for pass_ in range(3):  # 11 + 11 + 10 bits; positive floats sort as their bit patterns
            shift = 11 * pass_
            for k in range(2048):
                hist[k] = 0
            for i in range(v):
                hist[(src[i].key >> shift) & 2047] += 1
            p = 0
            for k in range(2048):
                c = hist[k]
                hist[k] = p
                p += c
            for i in range(v):
                k = (src[i].key >> shift) & 2047
                dst[hist[k]] = src[i]
                hist[k] += 1
            swap = src
            src = dst
            dst = swap
        for k in range(tiles):
            tile_start[k + 1] += tile_start[k]
            cursor[k] = tile_start[k]
        for i in range(v):
            if i + AHEAD < v:
                PREFETCH(&rect[src[i + AHEAD].g, 0])
                PREFETCH(&pair_start[src[i + AHEAD].g])
            g = src[i].g
            p = pair_start[g]
            for ty in range(rect[g, 1], rect[g, 3]):
                for tx in range(rect[g, 0], rect[g, 2]):
                    k = ty * tiles_x + tx
                    entries[cursor[k]] = <int32_t>g
                    entry_pair[cursor[k]] = <int32_t>p
                    cursor[k] += 1
                    p += 1
    free(src)
    free(dst)
    free(cursor)
    return v


cdef inline int row_span(const float* f, int y, int x_lo, int x_hi, int* x0, int* x1) noexcept nogil:
    """Pixels x0..x1 of row y (clipped to [x_lo, x_hi]) inside both the footprint ellipse (with the
    reference's margin) and the 3-sigma square; returns 0 when there are none."""
    cdef double mx = f[0], a = f[2], b = f[3], c = f[4], qmax = f[7], rad = f[8]
    cdef double dy = y + 0.5 - <double>f[1]
    cdef double disc = dmax((b * dy) * (b * dy) - a * (c * dy * dy - qmax), 0.0)
    cdef double ia = 1.0 / a
    cdef double half = sqrt(disc) * ia + 1e-4
    cdef double centre = -b * dy * ia
    cdef double lo = mx + dmax(centre - half, -rad), hi = mx + dmin(centre + half, rad)
    x0[0] = first_pixel(lo, x_lo, x_hi)
    x1[0] = last_pixel(hi, x_lo, x_hi)
    return x0[0] <= x1[0]


cdef inline float raw_alpha(const float* f, int x, float dy, float* gauss, float* dx) noexcept nogil:
    """o exp(-q/2) at pixel column x (before the 0.99 clamp), in float32 as the reference."""
    cdef float half = 0.5
    dx[0] = <float>x + half - f[0]
    cdef float power = -half * (f[2] * dx[0] * dx[0] + f[4] * dy * dy) - f[3] * dx[0] * dy
    gauss[0] = expf(power)
    return f[5] * gauss[0]


cdef struct Tiles:  # one frame's tile lists (bin_tiles) and the image they cover
    const float* feat  # [G, NF], project()'s
    const int32_t* tile_start  # [tiles + 1]
    const int32_t* entries  # the Gaussian of each entry, tile by tile, front to back
    int tiles_x
    int width
    int height


cdef struct Shading:  # how rasterize() colours a Gaussian: its mean and SH, seen from cam
    const float* means  # [G, 3]
    const float* sh  # [rows, nc, 3]
    const int32_t* sh_row  # [G] Gaussian -> SH row, or NULL: row g
    int nc
    const double* cam  # as project() takes it
    const float* bg  # [3]


cdef struct Pixels:  # what the forward pass writes: per pixel [height, width], per entry
    float* rgb
    float* alpha
    float* depth
    double* t_final
    int32_t* last
    float* entry_colour  # [entries, 3]
    uint8_t* contributes  # [G], or NULL: composite colours, else only mark (contributors())


cdef struct PixelGrads:  # what the backward pass reads per pixel and entry, and writes per pair
    const int32_t* entry_pair
    const float* entry_colour
    const float* bg
    const float* grad_rgb
    const float* grad_alpha
    const double* t_final
    const int32_t* last
    float* pair_grad  # [pairs, 9]


cdef class TileView:
    """A frame's :class:`.native_splat.Tiles` held for one kernel call, and its :c:type:`Tiles`."""
    cdef const float[:, ::1] feat
    cdef const int32_t[::1] tile_start, entries
    cdef Tiles c
    cdef int count  # tiles

    def __cinit__(self, tiles):
        self.feat, self.tile_start, self.entries = tiles.feat, tiles.tile_start, tiles.entries
        if self.feat.shape[1] != NF or self.tile_start.shape[0] < 1:
            raise ValueError("rasterize: mismatched shapes")
        self.c.feat = &self.feat[0, 0] if self.feat.shape[0] > 0 else NULL
        self.c.tile_start = &self.tile_start[0]
        self.c.entries = &self.entries[0] if self.entries.shape[0] > 0 else NULL
        self.c.tiles_x, self.c.width, self.c.height = tiles.tiles_x, tiles.width, tiles.height
        self.count = self.tile_start.shape[0] - 1


cdef void raster_tile(int tile, const Tiles* tl, const Shading* sg, Pixels* px) noexcept nogil:
    """Composites one tile. With ``px.contributes`` (and no SH in ``sg``) it only marks the Gaussians that
    contribute, taking exactly the decisions of the full pass, whose colours are then black."""
    cdef const float* feat = tl.feat
    cdef const int32_t* entries = tl.entries
    cdef int tx0 = (tile % tl.tiles_x) * TILE, ty0 = (tile // tl.tiles_x) * TILE
    cdef int tw = min(TILE, tl.width - tx0), th = min(TILE, tl.height - ty0)
    cdef double trans[TILE * TILE]
    cdef double acc[TILE * TILE * 4]
    cdef int32_t lst[TILE * TILE]
    cdef char done[TILE * TILE]
    cdef int rowleft[TILE]  # pixels of each row still compositing
    cdef int start = tl.tile_start[tile], end = tl.tile_start[tile + 1], npix = tw * th, ndone = 0
    cdef int e, k, y, x, x0, x1, y0, y1, pix, ch, have
    cdef int64_t g
    cdef const float* f
    cdef float a, gauss, dx, dy, half = 0.5
    cdef double tn, w
    cdef double col[3]
    for k in range(TILE * TILE):
        trans[k] = 1.0
        lst[k] = -1
        done[k] = 0
        acc[4 * k] = 0.0
        acc[4 * k + 1] = 0.0
        acc[4 * k + 2] = 0.0
        acc[4 * k + 3] = 0.0
    for k in range(TILE):
        rowleft[k] = tw
    for e in range(start, end):
        if ndone == npix:
            break
        if e + AHEAD < end:
            PREFETCH(feat + NF * entries[e + AHEAD])
        g = entries[e]
        f = feat + NF * g
        have = 0  # colour computed (only for Gaussians that contribute)
        y0 = first_pixel(f[1] - f[9], ty0, ty0 + th - 1)
        y1 = last_pixel(f[1] + f[9], ty0, ty0 + th - 1)
        for y in range(y0, y1 + 1):
            if rowleft[y - ty0] == 0 or not row_span(f, y, tx0, tx0 + tw - 1, &x0, &x1):
                continue
            dy = <float>y + half - f[1]
            for x in range(x0, x1 + 1):
                pix = (y - ty0) * TILE + x - tx0
                if done[pix]:
                    continue
                a = raw_alpha(f, x, dy, &gauss, &dx)
                if a < ALPHA_MIN:
                    continue
                if a > ALPHA_MAX:
                    a = ALPHA_MAX
                tn = trans[pix] * (1.0 - <double>a)
                if tn < T_MIN:  # as 3DGS: stop before the contribution that would take T below 1e-4
                    done[pix] = 1
                    ndone += 1
                    rowleft[y - ty0] -= 1
                    continue
                if not have and px.contributes != NULL:
                    px.contributes[g] = 1
                    col[0] = 0.0
                    col[1] = 0.0
                    col[2] = 0.0
                    have = 1
                elif not have:  # kept per entry for the backward pass (each entry is this tile's alone)
                    colour_of(sg.means + 3 * g, sg.sh + 3 * sg.nc * (sg.sh_row[g] if sg.sh_row != NULL else g),
                              sg.nc, sg.cam, col)
                    for ch in range(3):
                        px.entry_colour[3 * e + ch] = <float>col[ch]
                    have = 1
                w = a * trans[pix]
                acc[4 * pix] += w * col[0]
                acc[4 * pix + 1] += w * col[1]
                acc[4 * pix + 2] += w * col[2]
                acc[4 * pix + 3] += w * f[6]
                trans[pix] = tn
                lst[pix] = e - start
    for y in range(th):
        for x in range(tw):
            pix = y * TILE + x
            k = (ty0 + y) * tl.width + tx0 + x
            for ch in range(3):
                px.rgb[3 * k + ch] = <float>(acc[4 * pix + ch] + trans[pix] * sg.bg[ch])
            px.alpha[k] = <float>(1.0 - trans[pix])
            px.depth[k] = <float>acc[4 * pix + 3]
            px.t_final[k] = trans[pix]
            px.last[k] = lst[pix]


def rasterize(tiles, shading, pixels):
    """Front-to-back compositing of every tile of ``tiles`` (:class:`.native_splat.Tiles`), colours by
    ``shading`` (:class:`.native_splat.Shading`: Gaussian g's SH are row ``sh_row[g]`` of ``sh``, row g
    where ``sh_row`` is empty), into ``pixels`` (:class:`.native_splat.Pixels`): the image, and per
    pixel the final transmittance and the index (within its tile's list) of the last contribution, -1
    where none, and per entry the colour of the Gaussian (written only for entries that contribute:
    those the backward pass reads)."""
    cdef TileView tl = TileView(tiles)
    cdef const float[:, ::1] means = shading.means
    cdef const float[:, :, ::1] sh = shading.sh
    cdef const int32_t[::1] sh_row = shading.sh_row
    cdef const double[::1] cam = shading.cam
    cdef const float[::1] bg = shading.bg
    cdef float[:, :, ::1] rgb = pixels.rgb
    cdef float[:, ::1] alpha = pixels.alpha, depth = pixels.depth
    cdef double[:, ::1] t_final = pixels.t_final
    cdef int32_t[:, ::1] last = pixels.last
    cdef float[:, ::1] entry_colour = pixels.entry_colour
    cdef Shading sg
    cdef Pixels px
    cdef int tile
    sg.means = &means[0, 0] if means.shape[0] > 0 else NULL
    sg.sh = &sh[0, 0, 0] if sh.shape[0] > 0 else NULL
    sg.sh_row = &sh_row[0] if sh_row.shape[0] > 0 else NULL
    sg.nc = sh.shape[1]
    sg.cam = &cam[0]
    sg.bg = &bg[0]
    px.rgb = &rgb[0, 0, 0]
    px.alpha = &alpha[0, 0]
    px.depth = &depth[0, 0]
    px.t_final = &t_final[0, 0]
    px.last = &last[0, 0]
    px.entry_colour = &entry_colour[0, 0] if entry_colour.shape[0] > 0 else NULL
    px.contributes = NULL
    for tile in prange(tl.count, nogil=True, schedule="dynamic"):
        raster_tile(tile, &tl.c, &sg, &px)


def contributors(tiles, uint8_t[::1] contributes):
    """Marks (sets to 1) the Gaussians that :func:`rasterize` would take a colour from: the same
    compositing of ``tiles`` (:class:`.native_splat.Tiles`), on opacities alone. ``contributes`` must
    start zeroed."""
    cdef TileView tl = TileView(tiles)
    cdef int tile, width = tl.c.width, height = tl.c.height
    cdef float bg[3]
    cdef Shading sg  # no SH: only the background (black) is read
    cdef Pixels px  # scratch images, thrown away
    if tl.entries.shape[0] == 0:
        return
    bg[0] = 0
    bg[1] = 0
    bg[2] = 0
    sg.means = NULL
    sg.sh = NULL
    sg.sh_row = NULL
    sg.nc = 0
    sg.cam = NULL
    sg.bg = bg
    px.rgb = <float*>malloc(3 * width * height * sizeof(float))
    px.alpha = <float*>malloc(width * height * sizeof(float))
    px.depth = <float*>malloc(width * height * sizeof(float))
    px.t_final = <double*>malloc(width * height * sizeof(double))
    px.last = <int32_t*>malloc(width * height * sizeof(int32_t))
    px.entry_colour = NULL
    px.contributes = &contributes[0]
    for tile in prange(tl.count, nogil=True, schedule="dynamic"):
        raster_tile(tile, &tl.c, &sg, &px)
    free(px.rgb)
    free(px.alpha)
    free(px.depth)
    free(px.t_final)
    free(px.last)


cdef void raster_tile_backward(int tile, const Tiles* tl, const PixelGrads* pg) noexcept nogil:
    """One tile's (Gaussian, tile) pair gradients: its pixels' contributions walked back to front."""
    cdef const float* feat = tl.feat
    cdef const int32_t* entries = tl.entries
    cdef int width = tl.width
    cdef int tx0 = (tile % tl.tiles_x) * TILE, ty0 = (tile // tl.tiles_x) * TILE
    cdef int tw = min(TILE, width - tx0), th = min(TILE, tl.height - ty0)
    cdef double trans[TILE * TILE]
    cdef double rec[TILE * TILE * 3]  # colour behind, per unit transmittance (3DGS's accum_rec)
    cdef double dc[TILE * TILE * 3]
    cdef double dfin[TILE * TILE]  # (dL/dalpha - bg . dL/drgb) * T_final
    cdef int32_t lst[TILE * TILE]
    cdef int rowlast[TILE]  # the last contribution of each row
    cdef int start = tl.tile_start[tile], n = tl.tile_start[tile + 1] - start, maxlast = -1
    cdef int le, k, y, x, x0, x1, y0, y1, pix, ch
    cdef const float* col
    cdef const float* f
    cdef float* out
    cdef float a, raw, gauss, dx, dy, half = 0.5
    cdef double oma, tb, w, dlda, dpow
    cdef double gr[9]
    for k in range(TILE * TILE):
        lst[k] = -1
    for k in range(TILE):
        rowlast[k] = -1
    for y in range(th):
        for x in range(tw):
            pix = y * TILE + x
            k = (ty0 + y) * width + tx0 + x
            lst[pix] = pg.last[k]
            if pg.last[k] > rowlast[y]:
                rowlast[y] = pg.last[k]
            if pg.last[k] > maxlast:
                maxlast = pg.last[k]
            trans[pix] = pg.t_final[k]
            dfin[pix] = pg.grad_alpha[k]
            for ch in range(3):
                rec[3 * pix + ch] = 0.0
                dc[3 * pix + ch] = pg.grad_rgb[3 * k + ch]
                dfin[pix] -= pg.bg[ch] * pg.grad_rgb[3 * k + ch]
            dfin[pix] *= pg.t_final[k]
    for le in range(n - 1, -1, -1):
        for k in range(9):
            gr[k] = 0.0
        if le <= maxlast:
            if le >= AHEAD:
                PREFETCH(feat + NF * entries[start + le - AHEAD])
            f = feat + NF * entries[start + le]
            col = pg.entry_colour + 3 * (start + le)
            y0 = first_pixel(f[1] - f[9], ty0, ty0 + th - 1)
            y1 = last_pixel(f[1] + f[9], ty0, ty0 + th - 1)
            for y in range(y0, y1 + 1):
                if le > rowlast[y - ty0] or not row_span(f, y, tx0, tx0 + tw - 1, &x0, &x1):
                    continue
                dy = <float>y + half - f[1]
                for x in range(x0, x1 + 1):
                    pix = (y - ty0) * TILE + x - tx0
                    if le > lst[pix]:
                        continue
                    raw = raw_alpha(f, x, dy, &gauss, &dx)
                    if raw < ALPHA_MIN:
                        continue
                    a = raw if raw < ALPHA_MAX else ALPHA_MAX
                    oma = 1.0 - <double>a
                    tb = trans[pix] / oma  # transmittance in front of this contribution
                    w = a * tb
                    dlda = dfin[pix] / oma
                    for ch in range(3):
                        gr[6 + ch] += w * dc[3 * pix + ch]
                        dlda += tb * (col[ch] - rec[3 * pix + ch]) * dc[3 * pix + ch]
                        rec[3 * pix + ch] = a * col[ch] + oma * rec[3 * pix + ch]
                    trans[pix] = tb
                    if raw <= ALPHA_MAX:  # the clamp passes no gradient
                        gr[5] += dlda * gauss
                        dpow = dlda * raw
                        gr[0] += dpow * (f[2] * dx + f[3] * dy)
                        gr[1] += dpow * (f[4] * dy + f[3] * dx)
                        gr[2] -= 0.5 * dpow * dx * dx
                        gr[3] -= dpow * dx * dy
                        gr[4] -= 0.5 * dpow * dy * dy
        out = pg.pair_grad + 9 * <int64_t>pg.entry_pair[start + le]
        for k in range(9):
            out[k] = <float>gr[k]


def rasterize_backward(tiles, grads):
    """Gradients per (Gaussian, tile) pair of ``tiles`` (:class:`.native_splat.Tiles`) from those of the
    pixels, ``grads`` (:class:`.native_splat.PixelGrads`), into its ``pair_grad [P, 9]``: centre (2),
    conic (3), opacity, colour (3). Each tile writes only its own pairs, so threads never share an
    output."""
    cdef TileView tl = TileView(tiles)
    cdef const int32_t[::1] entry_pair = grads.entry_pair
    cdef const float[:, ::1] entry_colour = grads.entry_colour
    cdef const float[::1] bg = grads.bg
    cdef const float[:, :, ::1] grad_rgb = grads.grad_rgb
    cdef const float[:, ::1] grad_alpha = grads.grad_alpha
    cdef const double[:, ::1] t_final = grads.t_final
    cdef const int32_t[:, ::1] last = grads.last
    cdef float[:, ::1] pair_grad = grads.pair_grad
    cdef PixelGrads pg
    cdef int tile
    if tl.entries.shape[0] == 0:
        return
    pg.entry_pair = &entry_pair[0]
    pg.entry_colour = &entry_colour[0, 0]
    pg.bg = &bg[0]
    pg.grad_rgb = &grad_rgb[0, 0, 0]
    pg.grad_alpha = &grad_alpha[0, 0]
    pg.t_final = &t_final[0, 0]
    pg.last = &last[0, 0]
    pg.pair_grad = &pair_grad[0, 0]
    for tile in prange(tl.count, nogil=True, schedule="dynamic"):
        raster_tile_backward(tile, &tl.c, &pg)


cdef void project_backward_one(const float* mean, const float* quat, const float* scale, const float* sh,
                               int nc, const double* cam, const float* pair_grad, int64_t npairs,
                               int geometry, float* g_mean, float* g_quat, float* g_scale,
                               float* g_opacity, float* g_sh) noexcept nogil:
    cdef double fx = cam[15], fy = cam[16]
    cdef double gs[9]
    cdef double t[3]
    cdef double gr[9]
    cdef double b[16]
    cdef double bx[16]
    cdef double by[16]
    cdef double bz[16]
    cdef double d[3]
    cdef double gd[3]
    cdef double gt[3]
    cdef double gq[4]
    cdef double ga0[3]
    cdef double ga1[3]
    cdef double gj0[3]
    cdef double gj1[3]
    cdef double gcol[3]
    cdef Ewa e
    cdef const double* q = e.q  # the unit quaternion
    cdef double x, y, z, iz, ca, cb, cc, idet, idet2, gca, gcb, gcc, nd, col, dot, m, w
    cdef int64_t p
    cdef int k, j, ch
    for k in range(9):
        gs[k] = 0.0
    for p in range(npairs):
        for k in range(9):
            gs[k] += pair_grad[9 * p + k]
    g_opacity[0] = <float>gs[5]
    if gs[0] == 0 and gs[1] == 0 and gs[2] == 0 and gs[3] == 0 and gs[4] == 0 and gs[6] == 0 and gs[7] == 0 \
            and gs[8] == 0:  # hidden behind others (or transparent): nothing to take back
        for k in range(3 * nc):
            g_sh[k] = 0
        if geometry:
            for k in range(3):
                g_mean[k] = 0
                g_scale[k] = 0
            for k in range(4):
                g_quat[k] = 0
        return
    # colour: clamp at 0 (gradient where the argument is >= 0), SH basis, direction
    for k in range(3):
        d[k] = mean[k] - cam[12 + k]
    nd = dmax(sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), 1e-12)
    for k in range(3):
        d[k] = d[k] / nd
        gd[k] = 0.0
    sh_basis(nc, d[0], d[1], d[2], b, bx, by, bz)
    for ch in range(3):
        col = 0.5
        for k in range(nc):
            col += b[k] * sh[3 * k + ch]
        gcol[ch] = gs[6 + ch] if col >= 0 else 0.0
    for k in range(nc):
        for ch in range(3):
            g_sh[3 * k + ch] = <float>(b[k] * gcol[ch])
    if not geometry:
        return
    for k in range(nc):  # the colour's dependence on the view direction
        w = gcol[0] * sh[3 * k] + gcol[1] * sh[3 * k + 1] + gcol[2] * sh[3 * k + 2]
        gd[0] += w * bx[k]
        gd[1] += w * by[k]
        gd[2] += w * bz[k]
    dot = d[0] * gd[0] + d[1] * gd[1] + d[2] * gd[2]
    for k in range(3):
        gd[k] = (gd[k] - d[k] * dot) / nd
    # the projection, recomputed as in project_one
    for k in range(3):
        t[k] = cam[3 * k] * mean[0] + cam[3 * k + 1] * mean[1] + cam[3 * k + 2] * mean[2] + cam[9 + k]
    x = t[0]
    y = t[1]
    z = t[2]
    iz = 1.0 / z
    ewa_rows(quat, scale, cam, x, y, iz, &e)
    ca, cb, cc = e.ca, e.cb, e.cc
    idet = 1.0 / (ca * cc - cb * cb)
    idet2 = idet * idet
    # conic (cc, -cb, ca) / det back to the 2D covariance
    gca = gs[2] * (-cc * cc * idet2) + gs[3] * (cb * cc * idet2) + gs[4] * (idet - ca * cc * idet2)
    gcc = gs[2] * (idet - cc * ca * idet2) + gs[3] * (cb * ca * idet2) + gs[4] * (-ca * ca * idet2)
    gcb = gs[2] * (2 * cc * cb * idet2) + gs[3] * (-idet - 2 * cb * cb * idet2) + gs[4] * (2 * ca * cb * idet2)
    for j in range(3):
        ga0[j] = 2 * gca * e.a0[j] + gcb * e.a1[j]
        ga1[j] = 2 * gcc * e.a1[j] + gcb * e.a0[j]
        gj0[j] = 0.0
        gj1[j] = 0.0
    for j in range(3):  # A = J W M with M = R_q S: to J W's rows, M, then S and R_q
        w = 0.0
        for k in range(3):
            gj0[k] += ga0[j] * e.r[3 * k + j] * scale[j]
            gj1[k] += ga1[j] * e.r[3 * k + j] * scale[j]
            m = ga0[j] * e.jw0[k] + ga1[j] * e.jw1[k]  # dL/dM[k, j]
            w += m * e.r[3 * k + j]
            gr[3 * k + j] = m * scale[j]
        g_scale[j] = <float>w
    # J W's rows and the centre's projection, by camera-space x, y, z
    gt[0] = gs[0] * fx * iz
    gt[1] = gs[1] * fy * iz
    gt[2] = -(gs[0] * fx * x + gs[1] * fy * y) * iz * iz
    for k in range(3):
        gt[0] -= gj0[k] * fx * iz * iz * cam[6 + k]
        gt[1] -= gj1[k] * fy * iz * iz * cam[6 + k]
        gt[2] += gj0[k] * (-fx * cam[k] + 2 * fx * x * iz * cam[6 + k]) * iz * iz
        gt[2] += gj1[k] * (-fy * cam[3 + k] + 2 * fy * y * iz * cam[6 + k]) * iz * iz
    for k in range(3):
        g_mean[k] = <float>(cam[k] * gt[0] + cam[3 + k] * gt[1] + cam[6 + k] * gt[2] + gd[k])
    # rotation matrix back to the unit quaternion (w, x, y, z), then through the normalisation
    gq[0] = 2 * (-q[3] * gr[1] + q[2] * gr[2] + q[3] * gr[3] - q[1] * gr[5] - q[2] * gr[6] + q[1] * gr[7])
    gq[1] = 2 * (q[2] * gr[1] + q[3] * gr[2] + q[2] * gr[3] - 2 * q[1] * gr[4] - q[0] * gr[5]
                 + q[3] * gr[6] + q[0] * gr[7] - 2 * q[1] * gr[8])
    gq[2] = 2 * (-2 * q[2] * gr[0] + q[1] * gr[1] + q[0] * gr[2] + q[1] * gr[3] + q[3] * gr[5]
                 - q[0] * gr[6] + q[3] * gr[7] - 2 * q[2] * gr[8])
    gq[3] = 2 * (-2 * q[3] * gr[0] - q[0] * gr[1] + q[1] * gr[2] + q[0] * gr[3] - 2 * q[3] * gr[4]
                 + q[2] * gr[5] + q[1] * gr[6] + q[2] * gr[7])
    dot = q[0] * gq[0] + q[1] * gq[1] + q[2] * gq[2] + q[3] * gq[3]
    for k in range(4):
        g_quat[k] = <float>((gq[k] - q[k] * dot) * e.inv_n)


def project_backward(const float[:, ::1] means, const float[:, ::1] quats, const float[:, ::1] scales,
                     const float[:, :, ::1] sh, const int32_t[::1] sh_row, const double[::1] cam,
                     const int64_t[::1] pair_start, const float[:, ::1] pair_grad, bint geometry,
                     float[:, ::1] g_means, float[:, ::1] g_quats, float[:, ::1] g_scales,
                     float[::1] g_opacities, float[:, :, ::1] g_sh):
    """Per Gaussian, its pairs' gradients summed, then taken back through the SH colour and the
    projection to the inputs; every output row is written (zeros where the Gaussian has no pair).
    Without ``geometry`` only the opacity and SH gradients are computed (g_means, g_quats and
    g_scales are left as they are): the geometry is frozen. SH rows as in :func:`rasterize`: with
    ``sh_row``, only the Gaussians that contributed have one (and only they get a gradient)."""
    cdef Py_ssize_t g, row
    cdef int k, nc = sh.shape[1]
    cdef const float* pg = &pair_grad[0, 0] if pair_grad.shape[0] > 0 else NULL
    cdef bint rows = sh_row.shape[0] > 0
    for g in prange(means.shape[0], nogil=True, schedule="static"):
        row = sh_row[g] if rows else g
        if pair_start[g + 1] == pair_start[g]:
            for k in range(3):
                g_means[g, k] = 0
                g_scales[g, k] = 0
            for k in range(4):
                g_quats[g, k] = 0
            g_opacities[g] = 0
            if row >= 0:
                for k in range(3 * nc):
                    g_sh[row, k // 3, k % 3] = 0
            continue
        if row < 0:  # no contribution (rasterize took no colour): only the opacity's gradient, zero
            for k in range(3):
                g_means[g, k] = 0
                g_scales[g, k] = 0
            for k in range(4):
                g_quats[g, k] = 0
            g_opacities[g] = 0
            continue
        project_backward_one(&means[g, 0], &quats[g, 0], &scales[g, 0], &sh[row, 0, 0], nc, &cam[0],
                             pg + 9 * pair_start[g], pair_start[g + 1] - pair_start[g], geometry,
                             &g_means[g, 0],
                             &g_quats[g, 0], &g_scales[g, 0], &g_opacities[g], &g_sh[row, 0, 0])
