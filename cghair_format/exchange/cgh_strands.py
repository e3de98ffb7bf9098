"""A .cgh asset as strands: its decoded points (each strand's own, placeholders dropped), with the
view-independent colour (SH band 0)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..asset import HairAsset
from ..strands import Strands


def point_average(seg: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Per-segment values ``[S, P-1, D]`` to per-point ``[S, P, D]``: an inner point takes the mean of its
    two segments, a strand's end points (its last: point ``counts - 1``) their single segment."""
    out = np.empty((seg.shape[0], seg.shape[1] + 1, seg.shape[2]), np.float32)
    out[:, 0], out[:, -1] = seg[:, 0], seg[:, -1]
    out[:, 1:-1] = (seg[:, 1:] + seg[:, :-1]) / 2
    rows = np.arange(len(seg))
    out[rows, counts - 1] = seg[rows, counts - 2]
    return out


def strand_colors(asset: HairAsset) -> np.ndarray:
    """Per-point RGB ``[S, P, 3]`` (placeholders as they come): band-0 colour of the adjacent segments'
    Gaussians, averaged (:func:`point_average`; Gaussian ``i`` sits between points ``i`` and ``i+1``)."""
    from ..gaussians import SH_C0, strand_sh

    seg = np.maximum(0.0, SH_C0 * strand_sh(asset)[:, :, 0, :] + 0.5)  # [S, P-1, 3]
    return np.clip(point_average(seg, asset.counts), 0.0, 1.0)


def strands_from_asset(asset: HairAsset, colors: bool = True) -> Strands:
    """The asset's strands (each strand's own decoded points), widths ``2 d`` and band-0 colours."""
    from ..gaussians import decode_strands

    s = decode_strands(asset)
    s.colors = strand_colors(asset)[asset.real_points()] if colors else None
    s.widths = np.full(len(s.points), 2 * asset.thickness, np.float32)
    return s


def load(path: str | Path) -> Strands:
    from ..codec import read
    from ..errors import CghFormatError
    from ._common import StrandFileError

    try:
        asset = read(path)
    except CghFormatError as exc:  # name the file; the codec's message says what and where
        raise StrandFileError(path, f"{type(exc).__name__}: {exc}") from exc
    return strands_from_asset(asset)
