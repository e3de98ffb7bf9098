"""An animation of an asset: its cards' strips at each frame.

The rest pose is the asset as stored. Frame ``f`` replaces each card's spine and normals (half-widths
and groups stay the rest pose's); every strand point and Gaussian then follows through the format's own
decoding, spec 6.1 and 6.2, from the strands' stored ``(u, v, delta)``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..asset import Cards, HairAsset
from ..errors import AssetError
from ..geometry import strand_points


@dataclass
class Animation:
    """``F`` frames of card strips, ``fps`` a second, frame 0 at ``start`` seconds."""

    spine: np.ndarray  # [F, C, M+1, 3] float32
    normal: np.ndarray  # [F, C, M+1, 3] float32, unit, across the spine
    fps: float
    start: float = 0.0
    source: str = ""  # what made it, e.g. "simulate nod" or "fit anim.usda"

    @property
    def frames(self) -> int:
        return int(self.spine.shape[0])

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last."""
        return (self.frames - 1) / self.fps

    @classmethod
    def of_frames(cls, frames: list[Cards], fps: float, start: float = 0.0, source: str = "") -> Animation:
        return cls(np.stack([c.spine for c in frames]).astype(np.float32),
                   np.stack([c.normal for c in frames]).astype(np.float32), float(fps), float(start), source)

    def validate(self, rest: Cards) -> None:
        """:class:`AssetError` unless the frames fit ``rest`` (same cards and segments) and hold finite,
        unit-normal strips."""
        want = (self.frames, *rest.spine.shape)
        if self.spine.ndim != 4 or self.spine.shape != want or self.normal.shape != want:
            raise AssetError(f"animation frames must be [F, C, M+1, 3] = [F, {', '.join(map(str, rest.spine.shape))}]"
                             f", got spine {self.spine.shape} and normal {self.normal.shape}")
        if self.frames < 1:
            raise AssetError("an animation needs at least one frame")
        if not (np.isfinite(self.fps) and 0 < self.fps <= 1000) or not np.isfinite(self.start):
            raise AssetError(f"fps must lie in (0, 1000] and start be finite, got {self.fps} and {self.start}")
        for name in ("spine", "normal"):
            bad = ~np.isfinite(getattr(self, name)).all(axis=(1, 2, 3))
            if bad.any():
                raise AssetError(f"animation {name} of frame {int(np.argmax(bad))} holds NaN or infinite values")
        n = self.normal.astype(np.float64)
        if not (np.abs(np.sqrt((n * n).sum(-1)) - 1) < 1e-3).all():
            raise AssetError("animation normals must be unit vectors")

    def cards(self, rest: Cards, frame: int) -> Cards:
        """The cards at ``frame``."""
        if not 0 <= frame < self.frames:
            raise AssetError(f"frame {frame} is outside the animation's 0..{self.frames - 1}")
        return Cards(self.spine[frame], self.normal[frame], rest.half_width, rest.group)


def frame_asset(asset: HairAsset, animation: Animation, frame: int) -> HairAsset:
    """The asset at ``frame``: its cards moved, everything else shared with the rest pose."""
    return replace(asset, cards=animation.cards(asset.cards, frame))


def frame_points(asset: HairAsset, animation: Animation, frame: int) -> np.ndarray:
    """Every strand point ``[S, P, 3]`` (float32) at ``frame`` (spec 6.1 on the moved cards)."""
    return strand_points(animation.cards(asset.cards, frame), asset.strand_card, asset.uvd)
