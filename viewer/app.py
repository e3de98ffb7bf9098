"""The interactive window (``cgh view``): a thin glfw loop over :class:`Renderer` and
:class:`ViewerState`; all camera and toggle logic lives in :mod:`viewer.camera_control`."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from cghair_format import HairAsset
from cghair_format.animation import Animation
from cghair_format.atomic import atomic_path

from .camera_control import HELP, ORBIT_DEG_PER_PIXEL, BudgetControl, OrbitController, ViewerState
from .context import create_window
from .frame import SplatRenderer
from .motion import HELP as PLAY_HELP
from .motion import LIVE_HELP, ClipPlayer, LiveSimulation
from .renderer import create_renderer

IDLE_WAIT_S = 0.05  # how long a resting window waits for input before looking again


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Save an ``[H, W, 3|4]`` float image in [0, 1] as an 8-bit RGB PNG."""
    from PIL import Image

    rgb = (np.clip(image[..., :3], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    with atomic_path(path) as tmp:
        Image.fromarray(rgb).save(tmp)
    return Path(path)


def _key_name(glfw: Any, key: int) -> str:
    special = {glfw.KEY_ESCAPE: "ESCAPE", glfw.KEY_F12: "F12", glfw.KEY_EQUAL: "=", glfw.KEY_MINUS: "-",
               glfw.KEY_KP_ADD: "+", glfw.KEY_KP_SUBTRACT: "-", glfw.KEY_LEFT_BRACKET: "[",
               glfw.KEY_RIGHT_BRACKET: "]", glfw.KEY_SPACE: "SPACE", glfw.KEY_LEFT: "LEFT", glfw.KEY_RIGHT: "RIGHT",
               glfw.KEY_HOME: "HOME", glfw.KEY_END: "END", glfw.KEY_PAGE_UP: "PAGE_UP",
               glfw.KEY_PAGE_DOWN: "PAGE_DOWN"}
    if key in special:
        return special[key]
    if glfw.KEY_0 <= key <= glfw.KEY_9:
        return chr(ord("0") + key - glfw.KEY_0)
    if glfw.KEY_A <= key <= glfw.KEY_Z:
        return chr(ord("A") + key - glfw.KEY_A)
    return ""


def window_title(title: str, fps: float, drawn: str, budget: str, file_size: int, status: str) -> str:
    """The window's title: the last drawn frame's rate, what it drew (rasterizer, Gaussians,
    strands), the budget mode."""
    return f"{title} | {fps:.1f} fps | {drawn} | budget {budget} | {file_size / 1e6:.2f} MB | {status}"


class WindowInput:
    """Key and mouse state from glfw's callbacks: keys held (for flying), presses not yet handled,
    and mouse drags applied to the orbit controller (left: orbit; right, middle or shift: pan), or
    with ctrl to the motion: a live simulation's head (left: turn; right or middle: move), or a
    clip's time (the pointer across the window's width is the time slider)."""

    def __init__(self, glfw: Any, window: Any, state: ViewerState, press: tuple[str, ...] = (),
                 motion: ClipPlayer | LiveSimulation | None = None):
        self.glfw, self.window, self.state, self.motion = glfw, window, state, motion
        self.held: set[str] = set()
        self.pending: list[str] = list(press)
        self.buttons: set[int] = set()
        self.pos: tuple[float, float] | None = None
        self.shift = self.ctrl = False
        glfw.set_key_callback(window, self.on_key)
        glfw.set_mouse_button_callback(window, self.on_button)
        glfw.set_cursor_pos_callback(window, self.on_move)
        glfw.set_scroll_callback(window, lambda _w, _dx, dy: state.controller.zoom(dy))

    @property
    def active(self) -> bool:
        """Whether a key or button is held (the view may change without an event)."""
        return bool(self.held or self.buttons)

    def on_key(self, _w, key, _scancode, action, mods) -> None:
        name = _key_name(self.glfw, key)
        self.shift = bool(mods & self.glfw.MOD_SHIFT)
        if action == self.glfw.PRESS:
            self.held.add(name)
            self.pending.append(name)
        elif action == self.glfw.RELEASE:
            self.held.discard(name)

    def on_button(self, _w, button, action, mods) -> None:
        self.shift = bool(mods & self.glfw.MOD_SHIFT)
        self.ctrl = bool(mods & self.glfw.MOD_CONTROL)
        (self.buttons.add if action == self.glfw.PRESS else self.buttons.discard)(button)
        if action == self.glfw.PRESS and self.ctrl and isinstance(self.motion, ClipPlayer) and self.pos is not None:
            self.motion.seek(self.pos[0] / max(self.glfw.get_window_size(self.window)[0] - 1, 1))

    def on_move(self, _w, x, y) -> None:
        glfw, ctl = self.glfw, self.state.controller
        if self.pos is not None and self.buttons:
            dx, dy = x - self.pos[0], y - self.pos[1]
            second = glfw.MOUSE_BUTTON_RIGHT in self.buttons or glfw.MOUSE_BUTTON_MIDDLE in self.buttons
            height = glfw.get_framebuffer_size(self.window)[1]
            if self.ctrl and isinstance(self.motion, ClipPlayer):
                self.motion.seek(x / max(glfw.get_window_size(self.window)[0] - 1, 1))
            elif self.ctrl and isinstance(self.motion, LiveSimulation):
                if second:
                    self.motion.move(ctl.drag_offset(dx, dy, height))
                else:
                    self.motion.turn(dx * ORBIT_DEG_PER_PIXEL, dy * ORBIT_DEG_PER_PIXEL, ctl.axes()[0])
            elif second or self.shift:
                ctl.pan(dx, dy, height)
            else:
                ctl.orbit(dx, dy)
        self.pos = (x, y)


def _draw(renderer: SplatRenderer, camera: Any, settings: Any, budget: int | None) -> float:
    """Draw one frame of splats at ``budget``; returns its seconds (to the end of the GPU's work)."""
    renderer.budget = budget
    t0 = time.perf_counter()
    renderer.frame(camera, settings)
    renderer.ctx.finish()
    return time.perf_counter() - t0


def _screenshot(ctx: Any, width: int, height: int, path: Path) -> None:
    """Save what the window shows, overlays included."""
    raw = np.frombuffer(ctx.screen.read(viewport=(0, 0, width, height), components=3), np.uint8)
    save_png(raw.reshape(height, width, 3)[::-1] / 255.0, path)
    print(f"screenshot: {path}")


Motion = ClipPlayer | LiveSimulation


def _motion(asset: HairAsset, animation: Animation | None, simulate: bool, frames: range | None) -> Motion | None:
    """What moves the cards: the live solver, a clip, or nothing (a still asset)."""
    if simulate:
        return LiveSimulation(asset)
    return ClipPlayer(animation, asset.cards, frames) if animation is not None else None


def _press_keys(keys: WindowInput, state: ViewerState, budgets: BudgetControl, motion: Motion | None,
                window: Any) -> bool:
    """Apply the key presses since the last frame; returns whether a screenshot was asked for."""
    import glfw

    shot = False
    for key in keys.pending:
        if motion is not None and motion.press(key):
            continue
        action = state.press(key)
        if action == "quit":
            glfw.set_window_should_close(window, True)
        elif action == "budget":
            budgets.cycle()
        elif action == "screenshot":
            shot = True
    keys.pending.clear()
    return shot


def run_viewer(asset: HairAsset, *, title: str, file_size: int, width: int = 1280, height: int = 720,
               sort: str = "auto", rasterizer: str = "auto", budget: int | None = None,
               screenshot_dir: str | Path = ".", max_frames: int | None = None, press: tuple[str, ...] = (),
               animation: Animation | None = None, frames: range | None = None, simulate: bool = False,
               turn_sh: bool = True) -> int:
    """Open a window on ``asset`` and run until it is closed; returns the number of frames drawn.

    ``budget``: a fixed splat budget; by default it adapts while the camera (or the hair) moves (see
    :class:`BudgetControl`). The splats are drawn again only when the view, the settings, the budget or
    the cards change, so a resting camera on still hair costs one full-quality frame. ``animation``
    (its ``frames``, default all) plays in real time; ``simulate`` runs the strand solver live instead,
    the head dragged with ctrl; each Gaussian's SH turn with its segment unless ``turn_sh`` is false.
    ``max_frames`` closes the window after that many frames and ``press``
    replays key presses before the first frame (scripted sessions and tests).
    """
    import glfw

    window, ctx = create_window(width, height, title)
    try:
        motion = _motion(asset, animation, simulate, frames)
        renderer = create_renderer(ctx, asset, sort=sort, rasterizer=rasterizer, budget=budget,
                                   animated=motion is not None, turn_sh=turn_sh)
        state = ViewerState(OrbitController.framing(*renderer.bounds, asset.up_axis),
                            max_sh_degree=asset.appearance.sh_degree)
        budgets = BudgetControl(renderer.count, fixed=budget)
        keys = WindowInput(glfw, window, state, press, motion)
        drawn = last_view = None  # drawn: what the accumulation target holds, (view, pose, budget)
        frames_drawn, pose, fps, idle, last = 0, 0, 0.0, False, time.perf_counter()  # fps: of splat frames
        print(HELP if motion is None else f"{HELP}\n{LIVE_HELP if simulate else PLAY_HELP}")
        while not glfw.window_should_close(window) and (max_frames is None or frames_drawn < max_frames):
            if idle:  # nothing changed last time: sleep until an event (or a moment) instead of spinning
                glfw.wait_events_timeout(IDLE_WAIT_S)
            else:
                glfw.poll_events()
            now = time.perf_counter()
            state.fly(keys.held, now - last)
            shot = _press_keys(keys, state, budgets, motion, window)
            cards = motion.advance(now - last) if motion is not None else None
            last = now
            if cards is not None:
                renderer.move_cards(cards)
                pose += 1
            fb_w, fb_h = glfw.get_framebuffer_size(window)
            if fb_w == 0 or fb_h == 0:
                continue
            camera = state.controller.camera(fb_w, fb_h)
            s = state.settings
            view = (fb_w, fb_h, camera.world_to_camera.tobytes(), s)
            playing = motion is not None and motion.active
            moving, last_view = (last_view is not None and view != last_view) or playing, view
            frame_budget = budgets.budget(moving) if renderer.supports_budget else None  # OpenGL 3.3: every splat
            idle = (view, pose, frame_budget) == drawn and not keys.active and not playing
            if not s.hide_splats and (view, pose, frame_budget) != drawn:
                seconds = _draw(renderer, camera, s, frame_budget)
                budgets.record(seconds, renderer.drawn, moving)
                fps, drawn = 1.0 / max(seconds, 1e-6), (view, pose, frame_budget)
            ctx.screen.viewport = (0, 0, fb_w, fb_h)
            renderer.composite(camera, s, target=ctx.screen, flip_y=True)
            if shot:
                _screenshot(ctx, fb_w, fb_h, Path(screenshot_dir) /
                            f"cgh_view_{time.strftime('%Y%m%d_%H%M%S')}_{frames_drawn}.png")
            status = state.status() + (f" | {motion.status()}" if motion is not None else "")
            glfw.set_window_title(window, window_title(title, fps, renderer.describe(), budgets.label(), file_size,
                                                      status))
            glfw.swap_buffers(window)
            frames_drawn += 1
        renderer.release()
        return frames_drawn
    finally:
        glfw.destroy_window(window)
        glfw.terminate()
