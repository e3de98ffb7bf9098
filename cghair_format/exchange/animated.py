"""What the USD and Alembic exporters share for an animated asset: the check, the frame range and
each frame's geometry, all decoded from the moved cards exactly as the static export decodes the
rest pose (spec 6.1, 6.2), so a frame of the export is the asset at that frame.

Frame ``f`` of an :class:`~cghair_format.animation.Animation` lies at ``start + f / fps`` seconds:
USD time code ``start * fps + f`` (``timeCodesPerSecond = fps``), Alembic sample ``f`` of a uniform
time sampling of ``1 / fps`` seconds from ``start``.
"""

from __future__ import annotations

import numpy as np

from ..animation import Animation, frame_asset, frame_points
from ..asset import HairAsset
from ..errors import CghError


def check_animation(asset: HairAsset | None, animation: Animation) -> None:
    """:class:`CghError` unless ``animation`` moves ``asset``'s cards (same cards, finite frames)."""
    if asset is None:
        raise CghError("an animation moves a .cgh asset's cards: plain strands have none to export")
    animation.validate(asset.cards)


def frame_range(animation: Animation, spec: str) -> Animation:
    """Frames ``A:B`` of ``animation`` (``A`` included, ``B`` not, as a Python slice; either may be
    left out, negatives count from the end), each keeping its time: the clip starts ``A / fps`` later."""
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a, b = (int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise CghError(f"--frames takes A:B (first frame, one past the last), got {spec!r}") from None
    first, stop, _ = slice(a, b).indices(animation.frames)
    if stop <= first:
        raise CghError(f"--frames {spec} selects no frame of the animation's 0..{animation.frames - 1}")
    return Animation(animation.spine[first:stop], animation.normal[first:stop], animation.fps,
                     animation.start + first / animation.fps, animation.source)


def time_code(animation: Animation, frame: int) -> float:
    """The USD time code of ``frame``: frames counted from time 0 at ``fps`` a second."""
    return animation.start * animation.fps + frame


def curve_points(asset: HairAsset, animation: Animation, frame: int) -> np.ndarray:
    """Every strand's own points at ``frame``, flat ``[N, 3]`` float32, in the order of the static
    curves (:func:`~cghair_format.exchange.cgh_strands.strands_from_asset`)."""
    return np.ascontiguousarray(frame_points(asset, animation, frame)[asset.real_points()], np.float32)


def card_frame(asset: HairAsset, animation: Animation, frame: int):
    """The card mesh (:func:`~cghair_format.geometry.card_mesh`) at ``frame``."""
    from ..geometry import card_mesh

    return card_mesh(animation.cards(asset.cards, frame))


def gaussian_frame(asset: HairAsset, animation: Animation, frame: int):
    """The Gaussians' means, rotations (w, x, y, z), scales and opacities at ``frame``; their SH are the
    rest pose's (turning them with the segments is the decoder's business, not the export's)."""
    from ..gaussians import gaussian_frames

    return gaussian_frames(frame_asset(asset, animation, frame))
