"""Animated strands (strand caches): the same curves at every frame, read one frame at a time.

Like :mod:`cghair_format.exchange` for still strands, a reader per format chosen by extension
(:data:`CACHE_FORMATS`): USD time-sampled BasisCurves (:mod:`.usd_cache`) and Alembic animated
curves (:mod:`.alembic_cache`).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._common import StrandFileError, readable_file

# extension -> module (relative to this package) with load_cache(path) -> StrandCache
CACHE_FORMATS: dict[str, str] = {".usd": "usd_cache", ".usda": "usd_cache", ".usdc": "usd_cache",
                                 ".usdz": "usd_cache", ".abc": "alembic_cache"}


@dataclass
class StrandCache:
    """``frames`` frames of the same ``S`` curves (``counts [S]`` points each), ``fps`` a second from
    ``start`` seconds; ``read(f)`` gives frame ``f``'s points ``[N, 3]`` and curve counts ``[S]``."""

    path: str
    counts: np.ndarray  # [S] int64
    frames: int
    fps: float
    start: float
    read: Callable[[int], tuple[np.ndarray, np.ndarray]]
    meters_per_unit: float | None = None
    up_axis: str | None = None
    folder: object = None  # what ``read`` needs kept while frames are read (a temporary folder), or None

    def points(self, frame: int) -> np.ndarray:
        """Frame ``frame``'s points ``[N, 3]`` (float64), or a :class:`StrandFileError` when its curves or
        point counts differ from the first frame's or a point is NaN or infinite."""
        pts, counts = self.read(frame)
        if len(counts) != len(self.counts) or (counts != self.counts).any():
            raise StrandFileError(self.path, f"frame {frame} has other curves or point counts than the first "
                                             f"({len(counts)} curves, {int(counts.sum())} points, against "
                                             f"{len(self.counts)} and {int(self.counts.sum())})")
        pts = np.asarray(pts, np.float64)
        if not np.isfinite(pts).all():
            raise StrandFileError(self.path, f"frame {frame} holds NaN or infinite points")
        return pts

    def padded(self, points: int) -> Iterator[np.ndarray]:
        """Every frame as ``[S, points, 3]``: each curve's first ``points`` points, a shorter one repeating its
        last (the layout of an asset's strands, spec 3)."""
        starts = np.concatenate([[0], np.cumsum(self.counts)[:-1]])
        index = starts[:, None] + np.minimum(np.arange(points)[None, :], self.counts[:, None] - 1)
        for f in range(self.frames):
            yield self.points(f)[index]


def load_cache(path: str | Path) -> StrandCache:
    """The animated strands of ``path`` (``.usd .usda .usdc .usdz .abc``), by extension."""
    p, ext = readable_file(path, sorted(CACHE_FORMATS), "animated strands")
    return importlib.import_module(f"{__package__}.{CACHE_FORMATS[ext]}").load_cache(p)
