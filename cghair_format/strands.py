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
        return self

    def bbox_diagonal(self) -> float:
        return float(np.linalg.norm(self.points.max(0) - self.points.min(0)))
