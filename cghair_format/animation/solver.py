"""A strand solver in the style of the game engines' (TressFX): Verlet integration, then small,
separate passes over plain arrays, each tested alone.

Strands are ``[N, P, 3]`` float64 points whose first point (the root) rides the head rigidly. A step:

1. :func:`integrate`: Verlet with damping, gravity and wind;
2. :func:`global_shape`: the points near the root are pulled toward the rest pose carried by the head;
3. :func:`local_shape`: each segment is pulled toward its rest direction seen from its parent segment
   (bending stiffness);
4. :func:`collide` (and :func:`collide_field`, given a head mesh) and :func:`keep_lengths`, alternately:
   points pushed out of the head's capsules (and mesh), then every segment given its rest length, root to
   tip (follow the leader: exact after each pass).

Every pass moves positions only; the Verlet velocity is what they moved, less ``damping``.

Gravity acts as it does: the shape constraints are what hold a groom's style up, as in the game
engines, so a styled groom settles a little under its own weight when the simulation starts.

The settings are given for one reference substep (:data:`REFERENCE_STEP`, 1/240 s) and, for the bend,
one reference segment (1/:data:`REFERENCE_SEGMENTS` of its strand); :func:`per_substep`,
:func:`per_joint` and :func:`per_substep_damping` turn them into the share each pass applies, so a
strand moves alike at any point count and substep count (a card spine of 32 points as its strands of
100; 4 substeps a frame as 16). Why these conversions (figures in docs/animation.md):

- A pull of share ``s`` on a point acts as a spring whose stiffness over mass is ``s / (1 - s) / dt^2``
  (as compliance does in XPBD): the global shape keeps ``s / (1 - s)`` in proportion to ``dt^2``.
- The bend: joints that each keep ``1 - s`` of their error, root to tip, bend a strand under a load by
  a second difference of about ``(1 - s) / s`` times the load a joint, a curvature of that over ``h^2``
  with segments of length ``h``; ``s / (1 - s)`` in proportion to ``1 / h^2`` keeps the curvature at
  any point count. It is not scaled with ``dt``: the root-to-tip pass all but sets the strand's shape
  in each substep at these stiffnesses: under the built-in motions strands followed the same path
  at 4, 8 and 16 substeps within 0.7 % of their bounding box's diagonal with the share as it is, and
  5.6 % apart (16 against 8) with its odds scaled by ``dt^2``.
- The damping is kept per second: ``(1 - d)^(dt / REFERENCE_STEP)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import CghError
from .sdf import DistanceField

GRAVITY = 9.81  # m/s^2
REFERENCE_STEP = 1.0 / 240  # s: the substep the settings' shares are given for (8 substeps at 30 fps)
# the bend stiffness is given for a segment of 1/31 of its strand (a strand of 32 points, about a card
# spine's), a share of its own strand's length: every strand of a groom keeps its bend at any length
REFERENCE_SEGMENTS = 31


class UnstableSimulation(CghError, ValueError):
    """The solver met a non-finite point or a setting outside its stable range."""


@dataclass(frozen=True)
class SolverSettings:
    """What the solver does each step; the defaults suit hair at 30-60 frames a second."""

    # damping and the global pull are given for a substep of REFERENCE_STEP, the bend for a segment of
    # 1/REFERENCE_SEGMENTS of the strand; per_substep_damping, per_substep and per_joint convert them
    damping: float = 0.04  # share of the velocity lost every 1/240 s
    global_stiffness: float = 0.1  # pull toward the rest pose every 1/240 s, near the root
    global_range: float = 0.3  # share of each strand (from the root) the global shape holds
    local_stiffness: float = 0.9  # pull toward the rest bend a substep, on a segment of 1/31 of the strand
    length_iterations: int = 2  # collide + keep_lengths rounds per substep
    substeps: int = 8  # a frame: 240 Hz at 30 fps (at 120 Hz tips whipped: 2x the speeds)
    settle: float = 1.0  # seconds simulated with the head still before the first frame
    gravity: bool = True
    wind: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s^2 on a segment held across it
    wind_gust: float = 0.0  # relative strength of the seeded gusts, 0..1

    def check(self) -> None:
        """A setting outside the solver's stable range raises :class:`UnstableSimulation`."""
        for name in ("damping", "global_stiffness", "global_range", "local_stiffness", "wind_gust"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value <= 1):
                raise UnstableSimulation(f"{name} must lie in [0, 1], got {value}")
        if not 1 <= self.length_iterations <= 16 or not 1 <= self.substeps <= 64:
            raise UnstableSimulation("length_iterations must lie in 1..16 and substeps in 1..64")
        if not (np.isfinite(self.settle) and 0 <= self.settle <= 60):
            raise UnstableSimulation(f"settle must lie in [0, 60] seconds, got {self.settle}")
        if not np.isfinite(self.wind).all() or np.abs(self.wind).max() > 1e3:
            raise UnstableSimulation(f"wind must be finite and under 1000 m/s^2, got {self.wind}")


@dataclass
class StrandState:
    """Points now and one substep ago (their difference is the Verlet velocity), and the rest pose."""

    x: np.ndarray  # [N, P, 3] float64
    x_prev: np.ndarray  # [N, P, 3] float64
    rest: np.ndarray  # [N, P, 3] float64, the pose at the head's rest transform
    rest_length: np.ndarray  # [N, P-1] float64
    _bend: tuple[float, np.ndarray] | None = dataclasses.field(default=None, repr=False, compare=False)

    @classmethod
    def at_rest(cls, rest: np.ndarray) -> StrandState:
        rest = np.array(rest, np.float64)
        seg = np.diff(rest, axis=1)
        return cls(rest.copy(), rest.copy(), rest, np.sqrt((seg * seg).sum(-1)))

    def bend_pull(self, share: float) -> np.ndarray:
        """:func:`per_joint` of ``share`` on these rest lengths, computed once, not every substep."""
        if self._bend is None or self._bend[0] != share:
            self._bend = (share, per_joint(share, self.rest_length))
        return self._bend[1]


def rotate_between(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` turned by the smallest rotation taking unit ``a`` onto unit ``b`` (all ``[..., 3]``; Rodrigues
    without the angle). Opposite ``a`` and ``b`` have no smallest rotation: ``v`` is returned as it is."""
    c = (a * b).sum(-1, keepdims=True)
    k = np.cross(a, b)
    opposite = c < -1 + 1e-9
    scale = 1.0 / np.where(opposite, 1.0, 1.0 + c)
    turned = v * c + np.cross(k, v) + k * (k * v).sum(-1, keepdims=True) * scale
    return np.where(opposite, v, turned)


def _scaled_pull(share: float, ratio: np.ndarray | float) -> np.ndarray | float:
    """The pull whose odds ``s / (1 - s)`` are ``ratio`` times those of ``share`` (0 stays 0, 1 stays 1)."""
    return share * ratio / np.maximum(1.0 - share + share * ratio, 1e-300)


def per_substep(share: float, dt: float) -> float:
    """A pull given for a substep of :data:`REFERENCE_STEP` as applied in a substep of ``dt`` seconds: the
    same spring (odds ``s / (1 - s)`` in proportion to ``dt^2``)."""
    return float(_scaled_pull(share, (dt / REFERENCE_STEP) ** 2))


def per_joint(share: float, rest_length: np.ndarray) -> np.ndarray:
    """The bend pull of each joint, ``[N, P-1]`` (the joint at the start of each segment of ``rest_length
    [N, P-1]``): ``share`` on a segment of 1/:data:`REFERENCE_SEGMENTS` of its strand, its odds
    ``s / (1 - s)`` in proportion to one over the segment's share squared, so that a strand bends under a
    load as it does at 32 points at any point count."""
    total = rest_length.sum(1, keepdims=True)
    share_of_strand = rest_length / np.maximum(total, 1e-300)
    return _scaled_pull(share, 1.0 / np.maximum(share_of_strand * REFERENCE_SEGMENTS, 1e-150) ** 2)


def per_substep_damping(damping: float, dt: float) -> float:
    """The share of the velocity lost in a substep of ``dt`` for ``damping`` lost every :data:`REFERENCE_STEP`:
    the same decay a second."""
    return 1.0 - (1.0 - damping) ** (dt / REFERENCE_STEP)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.sqrt((v * v).sum(-1, keepdims=True)), 1e-30)


def integrate(state: StrandState, accel: np.ndarray, damping: float, dt: float) -> None:
    """Verlet: every point but the root moves by its damped velocity and ``accel`` (``[N, P, 3]`` or
    broadcastable) times ``dt^2``."""
    x, prev = state.x[:, 1:], state.x_prev[:, 1:]
    moved = x + (x - prev) * (1.0 - damping) + np.broadcast_to(accel, state.x.shape)[:, 1:] * (dt * dt)
    prev[...] = x
    x[...] = moved


def global_shape(state: StrandState, target: np.ndarray, stiffness: float, reach: int) -> None:
    """Points ``1 .. reach-1`` move ``stiffness`` of the way to ``target`` (the rest pose on the head)."""
    if reach > 1 and stiffness > 0:
        x = state.x[:, 1:reach]
        x += stiffness * (target[:, 1:reach] - x)


def local_shape(state: StrandState, target: np.ndarray, stiffness: float | np.ndarray) -> None:
    """Root to tip, each point moves ``stiffness`` (one share, or one a joint ``[N, P-1]``) of the way to
    where its rest segment (on the head, ``target``) would put it, turned as its parent segment has
    turned from rest; the first segment's parent is the scalp, which turns with the head (without it a
    stiff strand swings about its root as a rod)."""
    x = state.x
    pull = np.broadcast_to(np.asarray(stiffness, np.float64), (x.shape[0], x.shape[1] - 1))[..., None]
    if not pull.any():
        return
    rest_seg = np.diff(target, axis=1)
    x[:, 1] += pull[:, 0] * (x[:, 0] + rest_seg[:, 0] - x[:, 1])
    for k in range(1, x.shape[1] - 1):
        parent_now = _unit(x[:, k] - x[:, k - 1])
        parent_rest = _unit(rest_seg[:, k - 1])
        want = x[:, k] + rotate_between(parent_rest, parent_now, rest_seg[:, k])
        x[:, k + 1] += pull[:, k] * (want - x[:, k + 1])


def keep_lengths(state: StrandState) -> None:
    """Follow the leader: root to tip, each point is put back at its rest length from its parent, along
    the segment, so every length is exact after one pass. (Mueller et al. 2012 also take part of each
    correction off the parent's velocity; under gravity that leaves a velocity that never dies out, so
    the solver's damping is left to take out the energy the projection adds.)"""
    x = state.x
    for k in range(x.shape[1] - 1):
        seg = x[:, k + 1] - x[:, k]
        x[:, k + 1] = x[:, k] + _unit(seg) * state.rest_length[:, k, None]


@dataclass(frozen=True)
class Capsules:
    """Collision capsules in the head's rest frame: segment ``a -> b``, radius ``r`` (a sphere: ``a = b``)."""

    a: np.ndarray  # [Q, 3]
    b: np.ndarray  # [Q, 3]
    radius: np.ndarray  # [Q]

    def moved(self, rotation: np.ndarray, translation: np.ndarray) -> Capsules:
        return Capsules(self.a @ rotation.T + translation, self.b @ rotation.T + translation, self.radius)


def collide(state: StrandState, capsules: Capsules) -> None:
    """Points inside a capsule are pushed out to its surface along the way from its axis (roots stay)."""
    x = state.x[:, 1:]
    for a, b, r in zip(capsules.a, capsules.b, capsules.radius, strict=True):
        ab = b - a
        denom = float(ab @ ab)
        t = np.clip(((x - a) @ ab) / denom, 0.0, 1.0) if denom > 0 else np.zeros(x.shape[:-1])
        closest = a + t[..., None] * ab
        away = x - closest
        dist = np.sqrt((away * away).sum(-1))
        inside = dist < r
        if inside.any():
            x[inside] = closest[inside] + _unit(away[inside]) * r


def collide_field(state: StrandState, field: DistanceField, rotation: np.ndarray, translation: np.ndarray) -> None:
    """Points closer to the head mesh than ``field.margin`` (inside it: a negative distance) are pushed out
    along the field's gradient to that distance; the field lies in the head's rest frame, which the head
    has moved by ``x -> rotation x + translation`` (roots stay)."""
    x = state.x[:, 1:]
    local = (x - translation) @ rotation  # rotation^T (x - translation), row by row
    distance, gradient = field.sample(local, within=field.margin)
    hit = distance < field.margin
    if hit.any():
        out = local[hit] + _unit(gradient[hit]) * (field.margin - distance[hit])[:, None]
        x[hit] = out @ rotation.T + translation


def wind_accel(state: StrandState, wind: np.ndarray) -> np.ndarray:
    """Wind on each point: the part of ``wind`` across the point's segment (a strand feels no wind
    blowing along it), ``[N, P, 3]``."""
    seg = np.empty_like(state.x)
    seg[:, 1:] = state.x[:, 1:] - state.x[:, :-1]
    seg[:, 0] = seg[:, 1]
    t = _unit(seg)
    return wind - t * (t @ wind)[..., None]


def step(state: StrandState, settings: SolverSettings, rotation: np.ndarray, translation: np.ndarray,
         gravity: np.ndarray, wind: np.ndarray, capsules: Capsules | None, dt: float,
         field: DistanceField | None = None) -> None:
    """One substep of ``dt`` seconds with the head at ``x -> rotation x + translation``; ``gravity`` and
    ``wind`` in scene units per s^2; ``field``, the head mesh's distance field, collides beside the capsules."""
    with np.errstate(all="ignore"):  # a blow-up is refused below, in one line, not as numpy's warnings
        target = state.rest @ rotation.T + translation
        state.x[:, 0] = target[:, 0]
        state.x_prev[:, 0] = target[:, 0]
        accel = gravity if settings.gravity else np.zeros(3)
        if np.any(wind):
            accel = accel + wind_accel(state, wind)
        integrate(state, accel, per_substep_damping(settings.damping, dt), dt)
        reach = int(round(settings.global_range * state.x.shape[1]))
        global_shape(state, target, per_substep(settings.global_stiffness, dt), reach)
        local_shape(state, target, state.bend_pull(settings.local_stiffness))
        moved = capsules.moved(rotation, translation) if capsules is not None else None
        for _ in range(settings.length_iterations):
            if moved is not None:
                collide(state, moved)
            if field is not None:
                collide_field(state, field, rotation, translation)
            keep_lengths(state)
    if not np.isfinite(state.x).all():
        raise UnstableSimulation("the simulation produced non-finite points; lower the wind, raise the "
                                 "damping or the substeps")
