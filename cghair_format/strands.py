"""The strand type used everywhere: polylines of varying length, with optional colour and width."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import AssetError


@dataclass
class Strands:
    """``S`` polylines stored flat: strand ``i`` is ``points[offsets[i]:offsets[i+1]]``."""

    points: np.ndarray  # [N, 3] float32
    offsets: np.ndarray  # [S+1] int64, offsets[0] == 0, offsets[-1] == N
    colors: np.ndarray | None = None  # [N, 3] float32 in [0, 1], optional
    widths: np.ndarray | None = None  # [N] float32, optional, scene units
    meters_per_unit: float = 1.0
    up_axis: str = "Y"
    root_uv: np.ndarray | None = None  # [S, 2] float32, optional scalp (root) UV of each strand

    @property
    def count(self) -> int:
        return int(len(self.offsets) - 1)

    @property
    def point_counts(self) -> np.ndarray:
        return np.diff(self.offsets)

    def strand(self, i: int) -> np.ndarray:
        return self.points[self.offsets[i]:self.offsets[i + 1]]

    @classmethod
    def from_array(cls, points: np.ndarray, **kw) -> Strands:
        """Strands of equal length from ``[S, P, 3]``."""
        s, p = points.shape[:2]
        return cls(np.ascontiguousarray(points.reshape(-1, 3), np.float32),
                   np.arange(s + 1, dtype=np.int64) * p, **kw)

    def validate(self) -> Strands:
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise AssetError(f"strand points must be [N, 3], got {self.points.shape}")
        off = self.offsets
        if off.ndim != 1 or len(off) < 1 or off[0] != 0 or off[-1] != len(self.points) or (np.diff(off) < 0).any():
            raise AssetError("strand offsets must start at 0, never decrease and end at the point count")
        if not np.isfinite(self.points).all():
            raise AssetError("strand points contain NaN or infinite values")
        for name in ("colors", "widths"):
            a = getattr(self, name)
            if a is not None and len(a) != len(self.points):
                raise AssetError(f"strand {name} must have one entry per point")
        if self.root_uv is not None and self.root_uv.shape != (self.count, 2):
            raise AssetError(f"strand root_uv must be [S, 2] = [{self.count}, 2], got {self.root_uv.shape}")
        return self

    def bbox_diagonal(self) -> float:
        return float(np.linalg.norm(self.points.max(0) - self.points.min(0)))

    def to_array(self) -> np.ndarray:
        """``[S, P, 3]`` view of strands that all have ``P`` points (see :func:`resample`)."""
        counts = self.point_counts
        if self.count == 0 or (counts != counts[0]).any():
            raise AssetError("strands have different point counts; resample them first")
        return self.points.reshape(self.count, int(counts[0]), 3)


def bbox_diagonal(strands: Strands) -> float:
    """Length of the diagonal of the strands' axis-aligned bounding box (a scale for tolerances)."""
    return strands.bbox_diagonal()


def _strand_ids(offsets: np.ndarray) -> np.ndarray:
    return np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))


def _arclength_resample(points: np.ndarray, offsets: np.ndarray, n: int,
                        attrs: list[np.ndarray | None]) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """Resample flat strands to ``n`` points equally spaced in arc length (linear in between)."""
    s_count = len(offsets) - 1
    counts = np.diff(offsets)
    sid = _strand_ids(offsets)
    p = points.astype(np.float64)
    seg = np.zeros(len(p))
    if len(p) > 1:
        seg[1:] = np.linalg.norm(p[1:] - p[:-1], axis=1)
    seg[offsets[:-1][counts > 0]] = 0.0  # strand starts
    cum = np.cumsum(seg)
    cum -= np.repeat(cum[offsets[:-1][counts > 0]], counts[counts > 0])
    length = np.zeros(s_count)
    length[counts > 0] = cum[offsets[1:][counts > 0] - 1]
    local = np.arange(len(p)) - np.repeat(offsets[:-1], counts)
    # normalized parameter: arc length, or the point index for strands of zero length
    denom_idx = np.maximum(counts - 1, 1)
    t = np.where(np.repeat(length, counts) > 0, cum / np.maximum(np.repeat(length, counts), 1e-300),
                 local / np.repeat(denom_idx, counts))
    key = sid * 2.0 + t  # strands are 2 apart so their [0, 1] ranges never touch
    q = np.linspace(0.0, 1.0, n)
    qkey = (np.arange(s_count)[:, None] * 2.0 + q[None, :]).ravel()
    hi = np.searchsorted(key, qkey, side="left")
    start = np.repeat(offsets[:-1], n)
    end = np.repeat(offsets[1:] - 1, n)
    hi = np.minimum(np.maximum(hi, start + 1), end)  # a one-point strand gets hi == lo == its point
    lo = np.maximum(hi - 1, start)
    span = key[hi] - key[lo]
    w = np.where(span > 0, (qkey - key[lo]) / np.where(span > 0, span, 1), 0.0)[:, None]
    w = np.clip(w, 0, 1)
    out = p[lo] * (1 - w) + p[hi] * w
    res = []
    for a in attrs:
        if a is None:
            res.append(None)
            continue
        a2 = a.reshape(len(a), -1).astype(np.float64)
        v = a2[lo] * (1 - w) + a2[hi] * w
        res.append(v.reshape((-1,) + a.shape[1:]).astype(np.float32))
    return out.astype(np.float32), res


def resample(strands: Strands, n_points: int, method: str = "arclength") -> Strands:
    """Strands with exactly ``n_points`` points each, equally spaced along the curve.

    ``arclength``: along the polyline itself. ``bspline``: along the interpolating cubic B-spline
    through the points (smoother; passes through the original points), evaluated densely and
    then resampled by arc length. Colours and widths are interpolated linearly.
    """
    if n_points < 2:
        raise AssetError(f"resample needs at least 2 points per strand, got {n_points}")
    if method not in ("arclength", "bspline"):
        raise AssetError(f"resample method must be 'arclength' or 'bspline', got {method!r}")
    if (strands.point_counts < 1).any():
        raise AssetError("cannot resample a strand with no points")
    pts, off, attrs = strands.points, strands.offsets, [strands.colors, strands.widths]
    if method == "bspline":
        pts, off, attrs = _bspline_dense(strands)
    out, (colors, widths) = _arclength_resample(pts, off, n_points, attrs)
    return Strands(out, np.arange(strands.count + 1, dtype=np.int64) * n_points, colors, widths,
                   strands.meters_per_unit, strands.up_axis, strands.root_uv)


BSPLINE_OVERSAMPLE = 8


def _bspline_dense(strands: Strands):
    """Each strand's interpolating cubic B-spline (uniform parameter) sampled 8x more densely."""
    from scipy.interpolate import make_interp_spline

    counts = strands.point_counts
    dense_counts = (counts - 1) * BSPLINE_OVERSAMPLE + 1
    dense_off = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(dense_counts, out=dense_off[1:])
    pts = np.empty((int(dense_off[-1]), 3), np.float64)
    attrs_in = [a for a in (strands.colors, strands.widths)]
    attrs_out = [None if a is None else np.empty((len(pts),) + a.shape[1:], np.float32) for a in attrs_in]
    for p in np.unique(counts):  # strands of equal point count share one spline fit
        sel = np.flatnonzero(counts == p)
        idx = strands.offsets[sel][:, None] + np.arange(p)[None, :]  # [G, p]
        d = (p - 1) * BSPLINE_OVERSAMPLE + 1
        didx = dense_off[sel][:, None] + np.arange(d)[None, :]
        xd = np.linspace(0, p - 1, d)
        y = strands.points[idx].astype(np.float64)  # [G, p, 3]
        if p >= 2:
            spl = make_interp_spline(np.arange(p), y.transpose(1, 0, 2), k=min(3, p - 1))
            pts[didx] = spl(xd).transpose(1, 0, 2)
        else:
            pts[didx] = y
        lo = np.clip(np.floor(xd).astype(np.int64), 0, max(p - 2, 0))
        hi = np.minimum(lo + 1, p - 1)
        fr = (xd - lo)[None, :, None]
        for a, out in zip(attrs_in, attrs_out, strict=True):
            if a is not None:
                av = a[idx].reshape(len(sel), p, -1).astype(np.float64)
                out[didx] = (av[:, lo] * (1 - fr) + av[:, hi] * fr).reshape(out[didx].shape)
    return pts, dense_off, attrs_out


def densify(strands: Strands, target_count: int, seed: int = 0, n_points: int | None = None,
            neighbours: int = 4) -> Strands:
    """Reach ``target_count`` strands by adding strands interpolated between scalp neighbours.

    All strands are first resampled to ``n_points`` (default: the largest point count). Each new
    strand picks a random strand and two of its ``neighbours`` nearest roots, blends their
    root-relative shapes, colours and widths with random convex weights, and is placed at the same
    blend of their roots. Fewer than the current count returns a random subset.
    """
    from scipy.spatial import cKDTree

    if target_count < 1:
        raise AssetError(f"densify needs a positive target strand count, got {target_count}")
    n_points = int(n_points or strands.point_counts.max())
    base = resample(strands, n_points)
    rng = np.random.default_rng(seed)
    s = base.count
    if target_count <= s:
        keep = np.sort(rng.choice(s, target_count, replace=False))
        return _take(base, keep, n_points)
    arr = base.to_array().astype(np.float64)  # [S, P, 3]
    roots = arr[:, 0]
    k = min(neighbours + 1, s)
    _, nn = cKDTree(roots).query(roots, k=k)
    nn = nn.reshape(s, k)
    m = target_count - s
    first = rng.integers(0, s, m)
    if k > 1:
        others = nn[first][np.arange(m)[:, None], rng.integers(1, k, (m, 2))]  # two neighbours
    else:
        others = np.stack([first, first], 1)
    members = np.concatenate([first[:, None], others], 1)  # [M, 3]
    w = rng.dirichlet(np.ones(3), m)  # [M, 3] convex weights
    new_roots = np.einsum("mk,mkd->md", w, roots[members])
    shapes = arr[members] - roots[members][:, :, None, :]  # [M, 3, P, 3]
    new = new_roots[:, None, :] + np.einsum("mk,mkpd->mpd", w, shapes)
    out = np.concatenate([arr, new]).astype(np.float32)
    result = Strands.from_array(out, meters_per_unit=base.meters_per_unit, up_axis=base.up_axis)
    for name in ("colors", "widths"):
        a = getattr(base, name)
        if a is not None:
            a3 = a.reshape(s, n_points, -1).astype(np.float64)
            blended = np.einsum("mk,mkpc->mpc", w, a3[members])
            setattr(result, name, np.concatenate([a3, blended]).reshape((-1,) + a.shape[1:]).astype(np.float32))
    return result


def _take(strands: Strands, keep: np.ndarray, n_points: int) -> Strands:
    idx = (keep[:, None] * n_points + np.arange(n_points)[None, :]).ravel()
    return Strands(strands.points[idx], np.arange(len(keep) + 1, dtype=np.int64) * n_points,
                   None if strands.colors is None else strands.colors[idx],
                   None if strands.widths is None else strands.widths[idx],
                   strands.meters_per_unit, strands.up_axis)
