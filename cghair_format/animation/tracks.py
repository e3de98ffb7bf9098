"""Head motion: a rigid transform per frame, the built-in motions, and the head's collision proxy.

A track maps the rest pose to frame ``f`` by ``x -> rotation[f] x + translation[f]``. The built-in
motions turn the head about its own centre (shake, turn) or about the neck below it (nod), or bob it
as a walk does; lengths follow the scene's ``meters_per_unit``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CghError
from .solver import Capsules

MOTIONS = ("still", "nod", "shake", "turn", "walk")


@dataclass(frozen=True)
class HeadTrack:
    """``frames`` rigid transforms of the head, ``fps`` a second; frame 0 lies at ``start`` seconds of the
    clip's timeline (:meth:`at` counts from frame 0)."""

    rotation: np.ndarray  # [F, 3, 3] float64
    translation: np.ndarray  # [F, 3] float64
    fps: float
    start: float = 0.0

    @property
    def frames(self) -> int:
        return int(self.rotation.shape[0])

    def at(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """The transform at ``time`` seconds: rotations and translations blended linearly between frames
        and the rotation made orthonormal again (substeps fall between frames)."""
        f = float(np.clip(time * self.fps, 0, self.frames - 1))
        i = min(int(f), self.frames - 2) if self.frames > 1 else 0
        w = f - i if self.frames > 1 else 0.0
        j = min(i + 1, self.frames - 1)
        r = (1 - w) * self.rotation[i] + w * self.rotation[j]
        u, _, vt = np.linalg.svd(r)
        return u @ vt, (1 - w) * self.translation[i] + w * self.translation[j]


@dataclass(frozen=True)
class Head:
    """Where the head is at rest: its centre and radius (a sphere through the roots), and the up axis."""

    centre: np.ndarray  # [3]
    radius: float
    up: np.ndarray  # [3] unit

    def capsules(self) -> Capsules:
        c = self.centre[None]
        return Capsules(c, c, np.array([self.radius]))


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation of ``angle`` radians about the unit ``axis`` (right-handed)."""
    x, y, z = axis
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def fit_head(roots: np.ndarray, others: np.ndarray, up_axis: str) -> Head:
    """The head as a sphere: fitted to the strand ``roots [N, 3]`` (least squares), then shrunk until none
    of ``others [..., 3]`` (every other point that will be simulated: strand points past the root, card
    spines) lies inside it, so the rest pose collides with nothing."""
    roots = np.asarray(roots, np.float64)
    if len(roots) < 4:
        raise CghError(f"a head needs at least 4 strand roots to be fitted, got {len(roots)}")
    a = np.c_[2 * roots, np.ones(len(roots))]
    sol, *_ = np.linalg.lstsq(a, (roots * roots).sum(1), rcond=None)
    centre = sol[:3]
    radius = float(np.sqrt(max(sol[3] + centre @ centre, 0.0)))
    rest = np.asarray(others, np.float64).reshape(-1, 3)
    nearest = float(np.sqrt(((rest - centre) ** 2).sum(1)).min()) if len(rest) else radius
    up = np.array([0.0, 1.0, 0.0]) if up_axis == "Y" else np.array([0.0, 0.0, 1.0])
    if not np.isfinite(radius) or radius <= 0:
        raise CghError("the strand roots do not lie on a sphere-like scalp; give the head as capsules instead")
    return Head(centre, min(radius, nearest) * 0.98, up)


def head_of(asset) -> Head:
    """The head of a :class:`~cghair_format.asset.HairAsset` (:func:`fit_head`): a sphere through its strand
    roots, clear of every strand point and card spine."""
    from ..geometry import strand_points

    points = strand_points(asset.cards, asset.strand_card, asset.uvd)
    others = np.concatenate([points[:, 1:].reshape(-1, 3), asset.cards.spine[:, 1:].reshape(-1, 3)])
    return fit_head(points[:, 0], others, asset.up_axis)


def builtin_track(motion: str, head: Head, frames: int, fps: float, meters_per_unit: float) -> HeadTrack:
    """One of :data:`MOTIONS` over ``frames`` frames at ``fps``."""
    if motion not in MOTIONS:
        raise CghError(f"unknown motion {motion!r}; choose one of {', '.join(MOTIONS)}")
    t = np.arange(frames) / fps
    up, lateral = head.up, np.array([1.0, 0.0, 0.0])
    unit = 1.0 / meters_per_unit  # scene units in a metre
    pivot = head.centre
    if motion == "nod":  # about the neck, a head's radius below the centre
        pivot = head.centre - up * head.radius * 1.2
        angles, axis = np.radians(20) * np.sin(2 * np.pi * t / 1.5), lateral
    elif motion == "shake":
        angles, axis = np.radians(35) * np.sin(2 * np.pi * t / 1.2), up
    elif motion == "turn":  # ease out to 90 degrees over half the clip and back
        s = np.minimum(t / max(t[-1], 1e-9), 1.0) * 2.0 if frames > 1 else np.zeros(1)
        s = np.where(s <= 1, s, 2 - s)
        angles, axis = np.radians(90) * s * s * (3 - 2 * s), up
    elif motion == "walk":  # a sway of the head and a bob of 3 cm twice a stride
        angles, axis = np.radians(4) * np.sin(2 * np.pi * t / 1.1), up
    else:
        angles, axis = np.zeros(frames), up
    rotation = np.stack([axis_rotation(axis, a) for a in angles])
    translation = pivot - rotation @ pivot
    if motion == "walk":
        translation = translation + up * (0.03 * unit) * np.abs(np.sin(np.pi * t / 0.55))[:, None]
    return HeadTrack(rotation, translation, float(fps))
