"""Hair that moves in the viewer: where each frame's cards come from.

A motion gives the cards of the next displayed frame; the renderer uploads them and decodes the
geometry again (:meth:`viewer.renderer.Renderer.move_cards`). Two kinds:

- :class:`ClipPlayer` plays an :class:`~cghair_format.animation.Animation` in real time (frames are
  dropped, not slowed down, when drawing is slower than the clip), with keys to pause, step and scrub;
- :class:`LiveSimulation` runs the strand solver on the cards, one display frame at a time with a fixed
  number of substeps, the head turned (and moved) by the mouse.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from cghair_format import Cards, HairAsset
from cghair_format.animation import Animation
from cghair_format.errors import CghError

PLAY_KEYS = ("SPACE", "LEFT", "RIGHT", "HOME", "END", "PAGE_UP", "PAGE_DOWN")
HELP = ("space: play/pause | left/right: step | page up/down: scrub 1/10 | home/end: first/last frame | "
        "ctrl-click or ctrl-drag: the window's width is the time slider")
LIVE_HELP = "ctrl-drag: turn the head | ctrl-right-drag: move the head | space: pause the simulation"
LIVE_FPS = 30.0  # the live simulation's step: one display frame is this much simulated time
MAX_TURN_DEG = 15.0  # most the head turns in one live frame (a faster drag is spread over frames)


def parse_frames(text: str, frames: int) -> range:
    """``A:B`` (Python slice: A included, B not; either may be left out; negative from the end) or ``N``
    (one frame) as a range of an animation's ``frames``; :class:`CghError` when empty or malformed."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            n = int(parts[0])
            bounds = slice(n, n + 1 if n != -1 else None)
        elif len(parts) == 2:
            bounds = slice(*(int(p) if p.strip() else None for p in parts))
        else:
            raise ValueError
    except ValueError:
        raise CghError(f"--frames must be A:B or N (frame numbers), got {text!r}") from None
    chosen = range(frames)[bounds]
    if not chosen:
        raise CghError(f"--frames {text} selects no frame of the animation's 0..{frames - 1}")
    return chosen


class ClipPlayer:
    """An animation played in real time on a loop: :meth:`advance` moves by the seconds elapsed."""

    def __init__(self, animation: Animation, rest: Cards, frames: range | None = None):
        animation.validate(rest)
        self.animation, self.rest = animation, rest
        self.frames = frames or range(animation.frames)
        self.index = 0  # into ``frames``
        self.playing = True
        self._clock = 0.0  # frames of the clip elapsed since the current one was shown
        self._shown: int | None = None

    @property
    def frame(self) -> int:
        return self.frames[self.index]

    @property
    def active(self) -> bool:
        return self.playing and len(self.frames) > 1

    def press(self, key: str) -> bool:
        """Apply a playback key (:data:`PLAY_KEYS`); returns whether it was one."""
        n = len(self.frames)
        jump = {"LEFT": -1, "RIGHT": 1, "PAGE_DOWN": -max(1, n // 10), "PAGE_UP": max(1, n // 10)}
        if key == "SPACE":
            self.playing = not self.playing
        elif key in jump:
            self.playing = False
            self.index = (self.index + jump[key]) % n
        elif key in ("HOME", "END"):
            self.playing = False
            self.index = 0 if key == "HOME" else n - 1
        else:
            return False
        self._clock = 0.0
        return True

    def seek(self, fraction: float) -> None:
        """Pause at ``fraction`` (0: first frame, 1: last; clamped) of the clip: the time slider."""
        self.playing = False
        self.index = int(round(min(max(fraction, 0.0), 1.0) * (len(self.frames) - 1)))
        self._clock = 0.0

    def advance(self, seconds: float) -> Cards | None:
        """The cards to show now, or ``None`` when the frame shown is still the right one."""
        if self.playing:
            self._clock += seconds * self.animation.fps
            whole = int(self._clock)
            self._clock -= whole
            self.index = (self.index + whole) % len(self.frames)
        if self._shown == self.frame:
            return None
        self._shown = self.frame
        return self.animation.cards(self.rest, self.frame)

    def status(self) -> str:
        a = self.animation
        state = "playing" if self.playing else "paused"
        return f"frame {self.frame}/{a.frames - 1} ({a.start + self.frame / a.fps:.2f} s, {a.fps:g} fps) {state}"


def _blend(r0: np.ndarray, r1: np.ndarray, w: float) -> np.ndarray:
    """Rotations blended linearly and made orthonormal again (as :meth:`HeadTrack.at` does)."""
    u, _, vt = np.linalg.svd((1 - w) * r0 + w * r1)
    return u @ vt


class LiveSimulation:
    """The solver on an asset's card spines, stepped once per displayed frame (``1 / fps`` simulated
    seconds in ``settings.substeps`` substeps, whatever the wall clock), with the head's rigid transform
    set by the mouse (:meth:`turn`, :meth:`move`) about the head fitted to the strand roots."""

    def __init__(self, asset: HairAsset, settings: Any = None, fps: float = LIVE_FPS):
        from cghair_format.animation import SolverSettings, StrandState, settle
        from cghair_format.animation.solver import GRAVITY
        from cghair_format.animation.tracks import head_of

        self.settings = settings or SolverSettings()
        self.settings.check()
        self.rest, self.fps = asset.cards, float(fps)
        head = head_of(asset)
        self.centre, self.up, self.radius, self.capsules = head.centre, head.up, head.radius, head.capsules()
        unit = 1.0 / asset.meters_per_unit
        self.gravity = -head.up * GRAVITY * unit if self.settings.gravity else np.zeros(3)
        self.wind = np.asarray(self.settings.wind, np.float64) * unit
        self.state = StrandState.at_rest(asset.cards.spine)
        self.rotation, self.translation = np.eye(3), np.zeros(3)  # the head now
        self.target = (np.eye(3), np.zeros(3))  # where the mouse puts it by the next frame
        self.playing = True
        self.seconds = 0.0  # wall-clock time of the last frame's simulation
        self._fresh = True
        settle(self.state, self.settings, *self.target, self.gravity, self.wind, self.capsules,
               1.0 / (self.fps * self.settings.substeps))  # at rest, as drive.simulate starts

    @property
    def active(self) -> bool:
        return self.playing

    def turn(self, yaw_deg: float, pitch_deg: float, right: np.ndarray) -> None:
        """Turn the head's target about its centre: ``yaw`` about the up axis, ``pitch`` about ``right``
        (the camera's right axis), each at most :data:`MAX_TURN_DEG` a call."""
        from cghair_format.animation.tracks import axis_rotation

        yaw, pitch = (np.radians(np.clip(a, -MAX_TURN_DEG, MAX_TURN_DEG)) for a in (yaw_deg, pitch_deg))
        turn = axis_rotation(self.up, yaw) @ axis_rotation(np.asarray(right, np.float64) / np.linalg.norm(right), pitch)
        rotation, translation = self.target
        centre = rotation @ self.centre + translation
        self.target = (turn @ rotation, turn @ (translation - centre) + centre)

    def move(self, offset: np.ndarray) -> None:
        """Move the head's target by ``offset`` (scene units), at most a head radius a call."""
        offset = np.asarray(offset, np.float64)
        length = float(np.linalg.norm(offset))
        if length > self.radius:
            offset = offset * (self.radius / length)
        self.target = (self.target[0], self.target[1] + offset)

    def reset(self) -> None:
        """Bring the head back to its rest transform (the hair follows through the solver)."""
        self.target = (np.eye(3), np.zeros(3))

    def press(self, key: str) -> bool:
        if key == "SPACE":
            self.playing = not self.playing
            return True
        return False

    def _substeps(self, count: int, target: tuple[np.ndarray, np.ndarray]) -> None:
        """``count`` solver substeps taking the head linearly from where it is to ``target``."""
        from cghair_format.animation.solver import step

        r0, t0 = self.rotation, self.translation
        dt = 1.0 / (self.fps * self.settings.substeps)
        for i in range(1, count + 1):
            w = i / count
            self.rotation, self.translation = _blend(r0, target[0], w), (1 - w) * t0 + w * target[1]
            step(self.state, self.settings, self.rotation, self.translation, self.gravity, self.wind,
                 self.capsules, dt)

    def advance(self, seconds: float = 0.0) -> Cards | None:
        """The cards after one more display frame of simulation (``seconds``, the wall clock, is not
        used: the step is fixed for stability), or ``None`` while paused."""
        if not self.playing and not self._fresh:
            return None
        from cghair_format.animation import carried_normals

        t0 = time.perf_counter()
        if not self._fresh:
            self._substeps(self.settings.substeps, self.target)
        self._fresh = False
        spine = self.state.x
        normal = carried_normals(self.rest, spine, self.rotation)
        self.seconds = time.perf_counter() - t0
        return Cards(spine.astype(np.float32), normal.astype(np.float32), self.rest.half_width, self.rest.group)

    def status(self) -> str:
        state = "live" if self.playing else "paused"
        return f"simulation {state}, {1000 * self.seconds:.1f} ms/frame for {len(self.rest.spine)} cards"


def file_animation(path: str) -> Animation | None:
    """The animation stored in a .cgh, where this version of the format package reads them
    (``cghair_format.read_animation``); ``None`` when it holds none or cannot be read yet."""
    import cghair_format

    read = getattr(cghair_format, "read_animation", None)
    return read(path) if read is not None else None
