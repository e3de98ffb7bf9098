"""The interactive window (``cgh view``): a thin glfw loop over :class:`Renderer` and
:class:`ViewerState`; all camera and toggle logic lives in :mod:`viewer.camera_control`."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from cghair_format import HairAsset
from cghair_format.atomic import atomic_path

from .camera_control import HELP, OrbitController, ViewerState
from .context import create_window
from .fallback import create_renderer


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
               glfw.KEY_RIGHT_BRACKET: "]"}
    if key in special:
        return special[key]
    if glfw.KEY_0 <= key <= glfw.KEY_9:
        return chr(ord("0") + key - glfw.KEY_0)
    if glfw.KEY_A <= key <= glfw.KEY_Z:
        return chr(ord("A") + key - glfw.KEY_A)
    return ""


def run_viewer(asset: HairAsset, *, title: str, file_size: int, width: int = 1280, height: int = 720,
               sort: str = "auto", screenshot_dir: str | Path = ".", max_frames: int | None = None,
               press: tuple[str, ...] = ()) -> int:
    """Open a window on ``asset`` and run until it is closed; returns the number of frames drawn.

    ``max_frames`` closes the window after that many frames and ``press`` replays key presses
    before the first frame (scripted sessions and tests).
    """
    import glfw

    window, ctx = create_window(width, height, title)
    try:
        renderer = create_renderer(ctx, asset, sort=sort)
        lo, hi = renderer.scene.bounds
        state = ViewerState(OrbitController.framing(lo, hi, asset.up_axis), max_sh_degree=asset.appearance.sh_degree)
        held: set[str] = set()
        mouse = {"pos": None, "buttons": set(), "shift": False}
        pending: list[str] = list(press)
        frames = 0
        shot: Path | None = None

        def on_key(_w, key, _scancode, action, mods):
            name = _key_name(glfw, key)
            mouse["shift"] = bool(mods & glfw.MOD_SHIFT)
            if action == glfw.PRESS:
                held.add(name)
                pending.append(name)
            elif action == glfw.RELEASE:
                held.discard(name)

        def on_button(_w, button, action, mods):
            mouse["shift"] = bool(mods & glfw.MOD_SHIFT)
            (mouse["buttons"].add if action == glfw.PRESS else mouse["buttons"].discard)(button)

        def on_move(_w, x, y):
            if mouse["pos"] is not None and mouse["buttons"]:
                dx, dy = x - mouse["pos"][0], y - mouse["pos"][1]
                pan = (glfw.MOUSE_BUTTON_RIGHT in mouse["buttons"] or glfw.MOUSE_BUTTON_MIDDLE in mouse["buttons"]
                       or mouse["shift"])
                if pan:
                    state.controller.pan(dx, dy, glfw.get_framebuffer_size(window)[1])
                else:
                    state.controller.orbit(dx, dy)
            mouse["pos"] = (x, y)

        glfw.set_key_callback(window, on_key)
        glfw.set_mouse_button_callback(window, on_button)
        glfw.set_cursor_pos_callback(window, on_move)
        glfw.set_scroll_callback(window, lambda _w, _dx, dy: state.controller.zoom(dy))
        print(HELP)
        last = time.perf_counter()
        fps = 0.0
        while not glfw.window_should_close(window) and (max_frames is None or frames < max_frames):
            glfw.poll_events()
            now = time.perf_counter()
            dt, last = now - last, now
            fps = 0.9 * fps + 0.1 / max(dt, 1e-6) if fps else 1.0 / max(dt, 1e-6)
            state.fly(held, dt)
            fb_w, fb_h = glfw.get_framebuffer_size(window)
            if fb_w == 0 or fb_h == 0:
                continue
            camera = state.controller.camera(fb_w, fb_h)
            for key in pending:
                action = state.press(key)
                if action == "quit":
                    glfw.set_window_should_close(window, True)
                elif action == "screenshot":
                    shot = Path(screenshot_dir) / f"cgh_view_{time.strftime('%Y%m%d_%H%M%S')}_{frames}.png"
            pending.clear()
            s = state.settings
            if not s.hide_splats:
                renderer.preprocess(camera, s)
                renderer.sort()
                renderer.gather()
                renderer.draw(fb_w, fb_h)
            ctx.screen.viewport = (0, 0, fb_w, fb_h)
            renderer.composite(camera, s, target=ctx.screen, flip_y=True)
            if shot is not None:  # what the window shows, overlays included
                raw = np.frombuffer(ctx.screen.read(viewport=(0, 0, fb_w, fb_h), components=3), np.uint8)
                save_png(raw.reshape(fb_h, fb_w, 3)[::-1] / 255.0, shot)
                print(f"screenshot: {shot}")
                shot = None
            glfw.set_window_title(window, f"{title} | {fps:.1f} fps | {renderer.scene.count:,} Gaussians | "
                                          f"{file_size / 1e6:.2f} MB | {state.status()}")
            glfw.swap_buffers(window)
            frames += 1
        renderer.release()
        return frames
    finally:
        glfw.destroy_window(window)
        glfw.terminate()
