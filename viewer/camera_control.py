"""Camera control of the interactive viewer as pure logic (no GL, no window): testable headless.

:class:`OrbitController` holds an orbit camera (target, distance, azimuth, elevation) and applies
mouse orbit, pan and zoom, WASD fly and reset. :class:`ViewerState` maps key presses to the
viewer's toggles (cards, strands, group colours, SH degree, splat scale) and actions.
:class:`BudgetControl` chooses each frame's splat budget (level of detail).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from cghair_format.camera import Camera

from .frame import ViewSettings

ORBIT_DEG_PER_PIXEL = 0.3
ZOOM_PER_STEP = 0.9  # distance factor per scroll step
MIN_DISTANCE = 1e-3
MAX_ELEVATION = 89.0
FLY_SPEED = 0.5  # fraction of the orbit distance per second


@dataclass
class OrbitController:
    """An orbit camera around ``target``; angles in degrees, distance in scene units."""

    target: np.ndarray
    distance: float
    azimuth: float = 0.0
    elevation: float = 0.0
    up_axis: str = "Y"
    fov_y: float = 40.0
    _home: tuple | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.target = np.asarray(self.target, np.float64).copy()
        if self._home is None:
            self._home = (self.target.copy(), self.distance, self.azimuth, self.elevation)

    @classmethod
    def framing(cls, lo: np.ndarray, hi: np.ndarray, up_axis: str = "Y", fov_y: float = 40.0,
                azimuth: float = 0.0, elevation: float = 0.0) -> OrbitController:
        """A controller whose view contains the box ``[lo, hi]``."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
        distance = radius / math.sin(math.radians(fov_y) / 2) * 1.05
        return cls((lo + hi) / 2, distance, azimuth, elevation, up_axis, fov_y)

    def camera(self, width: int, height: int) -> Camera:
        return Camera.orbit(self.target, self.distance, self.azimuth, self.elevation, width, height,
                            self.up_axis, self.fov_y)

    def orbit(self, dx: float, dy: float) -> None:
        """Mouse drag by ``(dx, dy)`` pixels: turn around the target."""
        self.azimuth = (self.azimuth - dx * ORBIT_DEG_PER_PIXEL) % 360.0
        self.elevation = float(np.clip(self.elevation + dy * ORBIT_DEG_PER_PIXEL, -MAX_ELEVATION, MAX_ELEVATION))

    def zoom(self, steps: float) -> None:
        """Scroll by ``steps`` (positive: closer)."""
        self.distance = max(MIN_DISTANCE, self.distance * ZOOM_PER_STEP ** steps)

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World-space right, down and forward axes of the current camera."""
        r = self.camera(2, 2).world_to_camera[:3, :3]
        return r[0], r[1], r[2]

    def drag_offset(self, dx: float, dy: float, viewport_height: int) -> np.ndarray:
        """The world-space move that follows a drag of ``(dx, dy)`` pixels at the target's depth."""
        world_per_pixel = 2 * self.distance * math.tan(math.radians(self.fov_y) / 2) / max(viewport_height, 1)
        right, down, _ = self.axes()
        return (dx * right + dy * down) * world_per_pixel

    def pan(self, dx: float, dy: float, viewport_height: int) -> None:
        """Mouse drag by ``(dx, dy)`` pixels: move the target so the scene follows the pointer."""
        self.target = self.target - self.drag_offset(dx, dy, viewport_height)

    def fly(self, forward: float, right: float, up: float, seconds: float) -> None:
        """WASD flight: move the target (and camera) along the view axes for ``seconds``."""
        r, down, fwd = self.axes()
        step = FLY_SPEED * self.distance * seconds
        self.target = self.target + step * (forward * fwd + right * r - up * down)

    def reset(self) -> None:
        target, self.distance, self.azimuth, self.elevation = self._home
        self.target = target.copy()


# key name -> (action, argument)
KEYMAP: dict[str, tuple[str, object]] = {
    "C": ("toggle", "show_cards"), "L": ("toggle", "show_strands"), "G": ("toggle", "color_by_group"),
    "H": ("toggle", "hide_splats"), "T": ("toggle", "turn_sh"), "0": ("sh_degree", 0), "1": ("sh_degree", 1),
    "2": ("sh_degree", 2), "3": ("sh_degree", 3), "=": ("scale", 1.25), "+": ("scale", 1.25), "]": ("scale", 1.25),
    "-": ("scale", 0.8), "[": ("scale", 0.8),
    "B": ("budget", None), "R": ("reset", None), "P": ("screenshot", None), "F12": ("screenshot", None),
    "ESCAPE": ("quit", None),
}
# held keys -> (forward, right, up) flight direction
FLY_KEYS: dict[str, tuple[float, float, float]] = {
    "W": (1, 0, 0), "S": (-1, 0, 0), "D": (0, 1, 0), "A": (0, -1, 0), "E": (0, 0, 1), "Q": (0, 0, -1),
}
HELP = ("drag: orbit | right/middle drag or shift-drag: pan | scroll: zoom | WASD QE: fly | R: reset | "
        "C: cards | L: strands | G: group colours | H: hide splats | 0-3: SH degree | T: SH turn with moving hair | "
        "[/] or -/+: splat scale | "
        "B: splat budget (adaptive, full, 1/2 ... 1/16) | P: screenshot | Esc: quit")
TARGET_FRAME_S = 0.3  # the adaptive budget's frame time while the camera moves (about 3 fps)
MIN_BUDGET_FRACTION = 1 / 64  # the adaptive budget's floor, as a fraction of the Gaussians
BUDGET_FRACTIONS = (1 / 2, 1 / 4, 1 / 8, 1 / 16)  # the fixed budgets key B cycles through


@dataclass
class BudgetControl:
    """The splat budget of each frame: ``"adaptive"`` (while the camera moves, as many Gaussians as
    keep a frame near :data:`TARGET_FRAME_S`; all of them when it rests), ``"full"``, or a fixed
    number. Key B cycles adaptive, full, then fixed fractions of the Gaussians (and ``fixed``,
    the command line's ``--budget``, if given)."""

    total: int  # Gaussians in the scene
    fixed: int | None = None
    mode: str | int = "adaptive"
    moving_budget: float = 0.0  # the adaptive budget while moving, learned from frame times

    def __post_init__(self) -> None:
        if self.fixed is not None:
            self.mode = min(int(self.fixed), self.total)
        self.moving_budget = float(self.total)

    def modes(self) -> list[str | int]:
        fixed = [max(1, int(self.total * f)) for f in BUDGET_FRACTIONS]
        if self.fixed is not None and min(int(self.fixed), self.total) not in fixed:
            fixed = sorted({*fixed, min(int(self.fixed), self.total)}, reverse=True)
        return ["adaptive", "full", *fixed]

    def cycle(self) -> None:
        modes = self.modes()
        self.mode = modes[(modes.index(self.mode) + 1) % len(modes)] if self.mode in modes else modes[0]

    def budget(self, moving: bool) -> int | None:
        """The budget of the next frame (``None``: every Gaussian)."""
        if self.mode == "full" or (self.mode == "adaptive" and not moving):
            return None
        if self.mode == "adaptive":
            return None if self.moving_budget >= self.total else int(self.moving_budget)
        return int(self.mode)

    def record(self, seconds: float, drawn: int, moving: bool) -> None:
        """Learn from a frame's time: the adaptive budget scales with the frame time's error,
        halfway each frame (frame time is close to proportional to the Gaussians drawn)."""
        if self.mode != "adaptive" or not moving or seconds <= 0 or drawn <= 0:
            return
        want = drawn * TARGET_FRAME_S / seconds
        self.moving_budget = float(np.clip(np.sqrt(self.moving_budget * want),
                                           self.total * MIN_BUDGET_FRACTION, self.total))

    def label(self) -> str:
        if self.mode in ("adaptive", "full"):
            return str(self.mode)
        return f"{int(self.mode):,}"


@dataclass
class ViewerState:
    """Everything the keyboard changes, with the camera controller."""

    controller: OrbitController
    settings: ViewSettings = field(default_factory=ViewSettings)
    max_sh_degree: int = 3

    def press(self, key: str) -> str | None:
        """Apply a key press; returns ``"screenshot"``, ``"budget"`` or ``"quit"`` when the app must act."""
        action, arg = KEYMAP.get(key.upper(), (None, None))
        s = self.settings
        if action == "toggle":
            self.settings = replace(s, **{arg: not getattr(s, arg)})
        elif action == "sh_degree":
            self.settings = replace(s, sh_degree=min(int(arg), self.max_sh_degree))
        elif action == "scale":
            self.settings = replace(s, splat_scale=float(np.clip(s.splat_scale * float(arg), 0.05, 20.0)))
        elif action == "budget":
            return action
        elif action == "reset":
            self.controller.reset()
            self.settings = replace(s, splat_scale=1.0, sh_degree=None)
        elif action in ("screenshot", "quit"):
            return action
        return None

    def fly(self, held: set[str], seconds: float) -> None:
        """Move for the keys held during the last ``seconds``."""
        f = r = u = 0.0
        for key in held:
            df, dr, du = FLY_KEYS.get(key.upper(), (0, 0, 0))
            f, r, u = f + df, r + dr, u + du
        if f or r or u:
            self.controller.fly(f, r, u, seconds)

    def status(self) -> str:
        s = self.settings
        deg = "file" if s.sh_degree is None else str(s.sh_degree)
        flags = [name for name, on in (("cards", s.show_cards), ("strands", s.show_strands),
                                        ("groups", s.color_by_group), ("no splats", s.hide_splats),
                                        ("SH not turned", not s.turn_sh)) if on]
        return f"SH {deg}, scale {s.splat_scale:.2f}" + (f", {', '.join(flags)}" if flags else "")
