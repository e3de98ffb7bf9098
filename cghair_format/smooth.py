"""A low-pass filter along each strand's arc length: the root fixed, the strand's length kept.

Reconstructed strands zigzag from point to point (refinement's per-point moves, mostly),
and the strand coder pays for every zigzag: it predicts each point from its neighbours and stores the
miss. :func:`smooth_strands` averages each point with its neighbours, weighted by a Gaussian of
their distance along the strand (``sigma_mm`` millimetres, from the strands' ``meters_per_unit``;
the strand reflected through its root and its tip at the ends, which keeps both in place), gives the
length the zigzag took back as a straight extension of the tip, and spaces the same number of points
equally along the result (as :func:`cghair_format.strands.resample` does). A bend much longer than
``sigma_mm`` stays where it was (a curl of curvature k moves inwards by about k sigma^2 / 2), a zigzag
at the point spacing goes, uneven spacing with it (the coder pays for both), and the root and the
strand's length do not move. Smoothing the segments' directions instead and integrating them from
the root (tried first) left a higher curvature error at the same strand F1 (docs/reconstruct.md,
"Smoothing the reconstructed strands").
"""

from __future__ import annotations

import numpy as np

from .errors import AssetError
from .strands import Strands, _arclength_resample

BATCH = 1024  # strands filtered at once
# the width ``cgh reconstruct`` applies to its strands by default (ReconstructConfig.smooth_mm): none. On
# harolongo's 10,000 reconstructed strands every width tried (3, 6, 9 mm) lowered the strand F1 (3 mm / 30 deg:
# 0.549 -> 0.543 at 3 mm) and, trained, the test views' PSNR (28.78 -> 28.44 dB) while the file shrank by under
# 1 %; it lowers the curvature error (90.6 -> 81.9 1/m at 3 mm): docs/reconstruct.md, "Smoothing the
# reconstructed strands"
RECONSTRUCT_SMOOTH_MM = 0.0


def check_sigma(sigma_mm: float) -> float:
    """``sigma_mm`` as a float if it is a usable filter width (finite, >= 0), else an AssetError."""
    try:
        value = float(sigma_mm)
    except (TypeError, ValueError):
        raise AssetError(f"smoothing width must be a number of millimetres, got {sigma_mm!r}") from None
    if not np.isfinite(value) or value < 0:
        raise AssetError(f"smoothing width must be >= 0 mm (0: no smoothing), got {sigma_mm!r}")
    return value


def _smooth_group(points: np.ndarray, sigma: float) -> np.ndarray:
    """Strands ``[G, P, 3]`` (float64, world units) smoothed with a Gaussian of ``sigma`` units:
    the smoothed curve through ``P`` points, not yet equally spaced, and its tip extension."""
    g, p, _ = points.shape
    ds = np.linalg.norm(np.diff(points, axis=1), axis=2)  # [G, P-1]
    s = np.concatenate([np.zeros((g, 1)), np.cumsum(ds, axis=1)], 1)  # arc position of each point
    length = s[:, -1:]
    # each sample weighs by the arc length it stands for, so uneven spacing does not bias the mean
    share = np.concatenate([ds[:, :1], ds[:, 1:] + ds[:, :-1], ds[:, -1:]], 1) / 2
    # odd reflection through the root and through the tip: a straight line stays a straight line up to
    # the ends, and the ends themselves stay where they are
    root, tip = points[:, :1], points[:, -1:]
    ext_x = np.concatenate([2 * root - points[:, :0:-1], points, 2 * tip - points[:, -2::-1]], 1)
    ext_s = np.concatenate([-s[:, :0:-1], s, 2 * length - s[:, -2::-1]], 1)
    ext_w = np.concatenate([share[:, :0:-1], share, share[:, -2::-1]], 1)
    weight = np.exp(-0.5 * ((s[:, :, None] - ext_s[:, None, :]) / sigma) ** 2) * ext_w[:, None, :]
    total = weight.sum(2)[..., None]
    # a strand of zero length (every point the same) has no weights and stays as it is
    out = np.where(total > 0, np.einsum("gij,gjc->gic", weight, ext_x) / np.where(total > 0, total, 1), points)
    out[:, 0], out[:, -1] = points[:, 0], points[:, -1]
    # the zigzag's share of the length comes back as a straight extension of the tip
    new_ds = np.linalg.norm(np.diff(out, axis=1), axis=2)
    lost = np.maximum(length[:, 0] - new_ds.sum(1), 0.0)
    last = out[:, -1] - out[:, -2]
    last /= np.maximum(np.linalg.norm(last, axis=1, keepdims=True), 1e-300)
    return np.concatenate([out, (out[:, -1] + last * lost[:, None])[:, None]], 1)


def smooth_strands(strands: Strands, sigma_mm: float) -> Strands:
    """``strands`` low-passed along arc length with a Gaussian of ``sigma_mm`` millimetres (see the
    module docstring); 0 returns them unchanged. Colours, widths and root UVs are kept per point
    index (the points move along the strand by at most the spacing's unevenness)."""
    sigma_mm = check_sigma(sigma_mm)
    if sigma_mm == 0 or strands.count == 0:
        return strands
    sigma = sigma_mm / 1000.0 / strands.meters_per_unit
    points = strands.points.copy()
    counts = strands.point_counts
    for p in np.unique(counts[counts >= 3]):  # strands of equal point count are filtered together
        sel = np.flatnonzero(counts == p)
        for lo in range(0, len(sel), BATCH):  # bounded memory: BATCH x P x 3P weights at a time
            idx = strands.offsets[sel[lo:lo + BATCH]][:, None] + np.arange(p)[None, :]
            curve = _smooth_group(points[idx].astype(np.float64), sigma)  # [B, P+1, 3]
            offsets = np.arange(len(curve) + 1, dtype=np.int64) * (p + 1)
            points[idx] = _arclength_resample(curve.reshape(-1, 3), offsets, p, [])[0].reshape(len(curve), p, 3)
    return Strands(points, strands.offsets.copy(), strands.colors, strands.widths,
                   strands.meters_per_unit, strands.up_axis, strands.root_uv)


__all__ = ["RECONSTRUCT_SMOOTH_MM", "check_sigma", "smooth_strands"]
