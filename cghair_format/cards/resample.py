"""Strands of varying length to equal-length arrays ``[S, P, 3]`` for the card builder.

Uses :func:`cghair_format.strands.resample` when the interchange module provides it; until then
this minimal arc-length resampler (points, colours and widths, linearly interpolated).
"""

from __future__ import annotations

import numpy as np

from ..strands import Strands


def resample_arrays(strands: Strands, points: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Points ``[S, P, 3]``, colours ``[S, P, 3]`` or None, widths ``[S, P]`` or None, each strand
    resampled to ``points`` points evenly spaced along its arc length (one-point strands repeat)."""
    off = strands.offsets.astype(np.int64)
    pts = strands.points.astype(np.float64)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=-1)
    seg[off[1:-1] - 1] = 0.0  # no segment between the last point of a strand and the next strand's first
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    start = cum[off[:-1]]
    length = cum[np.maximum(off[1:] - 1, off[:-1])] - start
    # target arc length of every output point, as a global coordinate along the concatenation
    frac = np.linspace(0.0, 1.0, points)
    target = start[:, None] + length[:, None] * frac[None, :]  # [S, P]
    lo = off[:-1, None]
    hi = np.maximum(off[1:, None] - 1, lo)
    # cum is non-decreasing; search inside each strand's own range
    idx = np.searchsorted(cum, target, side="right") - 1
    idx = np.clip(idx, lo, np.maximum(hi - 1, lo))
    nxt = np.minimum(idx + 1, hi)
    span = cum[nxt] - cum[idx]
    w = np.where(span > 0, (target - cum[idx]) / np.where(span > 0, span, 1.0), 0.0).clip(0, 1)

    def interp(values: np.ndarray) -> np.ndarray:
        v = values.astype(np.float64)
        a, b = v[idx], v[nxt]
        ww = w.reshape(w.shape + (1,) * (v.ndim - 1))
        return a + (b - a) * ww

    out = interp(pts)
    colors = interp(strands.colors).clip(0, 1) if strands.colors is not None else None
    widths = interp(strands.widths) if strands.widths is not None else None
    return out, colors, widths
