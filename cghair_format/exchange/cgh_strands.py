"""A .cgh asset as strands: its decoded points, with the view-independent colour (SH band 0)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..asset import HairAsset
from ..strands import Strands


def strand_colors(asset: HairAsset) -> np.ndarray:
    """Per-point RGB ``[S, P, 3]``: band-0 colour of the adjacent segments' Gaussians, averaged.

    Gaussian ``i`` of a strand sits between points ``i`` and ``i+1``; an inner point takes the
    mean of its two segments, the end points their single segment.
    """
    from ..gaussians import SH_C0, strand_sh

    seg = np.maximum(0.0, SH_C0 * strand_sh(asset)[:, :, 0, :] + 0.5)  # [S, P-1, 3]
    pts = np.empty((seg.shape[0], seg.shape[1] + 1, 3), np.float32)
    pts[:, 0] = seg[:, 0]
    pts[:, -1] = seg[:, -1]
    pts[:, 1:-1] = (seg[:, 1:] + seg[:, :-1]) / 2
    return np.clip(pts, 0.0, 1.0)


def strands_from_asset(asset: HairAsset, colors: bool = True) -> Strands:
    """The asset's strands (decoded points), widths ``2 d`` and band-0 colours."""
    from ..gaussians import decode_points

    pts = decode_points(asset)
    s = Strands.from_array(pts, meters_per_unit=asset.meters_per_unit, up_axis=asset.up_axis,
                           root_uv=asset.root_uv)
    s.widths = np.full(len(s.points), 2 * asset.thickness, np.float32)
    if colors:
        s.colors = strand_colors(asset).reshape(-1, 3)
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
