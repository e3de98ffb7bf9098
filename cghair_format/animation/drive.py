"""Strands and cards driven by the solver, frame by frame.

:func:`simulate` runs the solver on any strands (the cards' spines, or every strand of a groom for
reference) and returns their points at each frame. :func:`card_frames` does it for the cards of an
asset and carries each card's normals along: a normal turns with the smallest rotation that takes its
rest tangent (turned by the head) onto the moved tangent, so a card twists only as its spine bends.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from ..asset import Cards
from ..errors import CghError
from ..geometry import spine_tangents
from .clip import Animation
from .sdf import DistanceField
from .solver import GRAVITY, Capsules, SolverSettings, StrandState, rotate_between, step
from .tracks import HeadTrack, builtin_track, head_of

# damping while the groom settles: heavy, so that it comes to rest within the settle and the first frame
# starts still (a swing stopped half way would start again once the motion begins)
SETTLE_DAMPING = 0.3


@dataclass(frozen=True)
class Scene:
    """What the strands move in: the head's track, collision capsules and mesh (its distance field), the
    units and up axis."""

    track: HeadTrack
    capsules: Capsules | None
    meters_per_unit: float
    up: np.ndarray  # [3] unit
    seed: int = 0
    field: DistanceField | None = None


def _gusts(seed: int, times: np.ndarray, strength: float) -> np.ndarray:
    """A smooth, seeded factor around 1 for the wind at ``times``: three sines of random phase."""
    rng = np.random.default_rng(seed)
    periods, phases = rng.uniform(0.7, 3.0, 3), rng.uniform(0, 2 * np.pi, 3)
    wave = np.sin(2 * np.pi * times[:, None] / periods + phases).mean(1)
    return 1.0 + strength * wave


def simulate(rest: np.ndarray, scene: Scene, settings: SolverSettings) -> Iterator[np.ndarray]:
    """The points ``[N, P, 3]`` (float64) of strands at rest pose ``rest`` at each frame of the track. The
    first is the rest pose at the track's first transform after ``settings.settle`` seconds of the head
    held still, at rest: the groom as gravity and its shape constraints hold it, without the jolt of
    letting it fall at the first frame."""
    settings.check()
    state = StrandState.at_rest(rest)
    fps, sub = scene.track.fps, settings.substeps
    dt = 1.0 / (fps * sub)
    unit = 1.0 / scene.meters_per_unit
    gravity = -scene.up * GRAVITY * unit
    wind = np.asarray(settings.wind, np.float64) * unit
    gusts = _gusts(scene.seed, np.arange(scene.track.frames * sub) * dt, settings.wind_gust)
    rotation, translation = scene.track.at(0.0)
    state.x[...] = state.rest @ rotation.T + translation
    state.x_prev[...] = state.x
    settle(state, settings, rotation, translation, gravity, wind, scene.capsules, dt, scene.field)
    yield state.x.copy()
    for f in range(1, scene.track.frames):
        for s in range(sub):
            i = (f - 1) * sub + s + 1
            rotation, translation = scene.track.at(i * dt)
            step(state, settings, rotation, translation, gravity, wind * gusts[i], scene.capsules, dt, scene.field)
        yield state.x.copy()


def settle(state: StrandState, settings: SolverSettings, rotation: np.ndarray, translation: np.ndarray,
           gravity: np.ndarray, wind: np.ndarray, capsules: Capsules | None, dt: float,
           field: DistanceField | None = None) -> None:
    """``settings.settle`` seconds of substeps of ``dt`` with the head held at its transform and the damping
    at least :data:`SETTLE_DAMPING`, then the velocity dropped: the groom at rest as gravity and its shape
    constraints hold it, from which a clip or a live simulation starts."""
    settling = replace(settings, damping=max(settings.damping, SETTLE_DAMPING))
    for _ in range(int(round(settings.settle / dt))):
        step(state, settling, rotation, translation, gravity, wind, capsules, dt, field)
    state.x_prev[...] = state.x


def carried_normals(rest: Cards, spine: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """The normals of cards whose spines moved to ``spine [C, M+1, 3]`` with the head turned by
    ``rotation``: each rest normal turned with the head, then by the smallest rotation from its rest
    tangent (turned) to its new tangent, and made perpendicular to it again. Float64."""
    t_rest = spine_tangents(np.asarray(rest.spine, np.float64)) @ rotation.T
    t_now = spine_tangents(np.asarray(spine, np.float64))
    n = rotate_between(t_rest, t_now, np.asarray(rest.normal, np.float64) @ rotation.T)
    n -= t_now * (n * t_now).sum(-1, keepdims=True)
    return n / np.maximum(np.sqrt((n * n).sum(-1, keepdims=True)), 1e-30)


def card_frames(cards: Cards, scene: Scene, settings: SolverSettings) -> Iterator[Cards]:
    """The cards at each frame: spines simulated, normals carried, widths and groups as at rest."""
    for f, spine in enumerate(simulate(cards.spine, scene, settings)):
        rotation, _ = scene.track.at(f / scene.track.fps)
        yield Cards(spine.astype(np.float32), carried_normals(cards, spine, rotation).astype(np.float32),
                    cards.half_width, cards.group)


def simulated_animation(asset, motion: str, frames: int, fps: float, settings: SolverSettings | None = None,
                        seed: int = 0, collider: DistanceField | None = None) -> Animation:
    """An animation of a :class:`~cghair_format.asset.HairAsset`: its cards simulated under the built-in head
    ``motion`` (:data:`~.tracks.MOTIONS`) for ``frames`` frames at ``fps``, the head fitted to its roots
    (a sphere that is also the collider unless a head mesh's field is given: :func:`tracked_animation`)."""
    if frames < 1:
        raise CghError(f"a simulated animation needs at least one frame, got {frames}")
    track = builtin_track(motion, head_of(asset), frames, fps, asset.meters_per_unit)
    return tracked_animation(asset, track, settings, seed, collider, f"simulate {motion}")


def tracked_animation(asset, track: HeadTrack, settings: SolverSettings | None = None, seed: int = 0,
                      collider: DistanceField | None = None, source: str = "simulate track") -> Animation:
    """An animation of a :class:`~cghair_format.asset.HairAsset`: its cards simulated on the head ``track``
    (built in, or read from a file: :func:`~.track_file.head_track_from_file`), colliding with the head
    mesh's distance field ``collider`` (:func:`~.collider.collider_field`) or else with a sphere fitted to
    the roots (:func:`~.tracks.head_of`)."""
    up = np.array([0.0, 1.0, 0.0]) if asset.up_axis == "Y" else np.array([0.0, 0.0, 1.0])
    capsules = head_of(asset).capsules() if collider is None else None
    scene = Scene(track, capsules, asset.meters_per_unit, up, seed, collider)
    frames_ = list(card_frames(asset.cards, scene, settings or SolverSettings()))
    return Animation.of_frames(frames_, track.fps, track.start, source)
