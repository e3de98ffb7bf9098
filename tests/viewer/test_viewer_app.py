"""The window loop of ``cgh view`` (viewer/app.py) on the headless context, with glfw replaced by a
stand-in that records titles: the budget key, the title, and redrawing only what changed. The
real window runs in tests/viewer/test_viewer_window.py where Xvfb exists."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pytest

from cghair_format.examples import example_asset

pytestmark = pytest.mark.gl


class _Context:
    """The headless context with a texture framebuffer standing in for the window's."""

    def __init__(self, ctx, width, height):
        self._ctx = ctx
        self.screen = ctx.framebuffer([ctx.texture((width, height), 4)])

    def __getattr__(self, name):
        return getattr(self._ctx, name)


def _fake_glfw(width, height):
    titles: list[str] = []
    names = ("KEY_ESCAPE", "KEY_F12", "KEY_EQUAL", "KEY_MINUS", "KEY_KP_ADD", "KEY_KP_SUBTRACT",
             "KEY_LEFT_BRACKET", "KEY_RIGHT_BRACKET", "KEY_0", "KEY_9", "KEY_A", "KEY_Z", "MOUSE_BUTTON_RIGHT",
             "MOUSE_BUTTON_MIDDLE", "PRESS", "RELEASE", "KEY_SPACE", "KEY_LEFT", "KEY_RIGHT",
             "KEY_HOME", "KEY_END", "KEY_PAGE_UP", "KEY_PAGE_DOWN")
    bits = {"MOD_SHIFT": 1, "MOD_CONTROL": 2}  # modifier flags, as glfw's
    glfw = SimpleNamespace(**{n: i for i, n in enumerate(names)}, **bits, titles=titles)
    for name in ("set_key_callback", "set_mouse_button_callback", "set_cursor_pos_callback", "set_scroll_callback",
                 "poll_events", "wait_events_timeout", "swap_buffers", "destroy_window", "terminate",
                 "set_window_should_close"):
        setattr(glfw, name, lambda *a: None)
    glfw.window_should_close = lambda w: False
    glfw.get_framebuffer_size = glfw.get_window_size = lambda w: (width, height)
    glfw.set_window_title = lambda w, title: titles.append(title)
    return glfw


def _record_drawn_budgets(app, monkeypatch) -> list:
    """The budget of every frame the viewer draws (presenting the last frame again is not drawing)."""
    draws = []
    real_create = app.create_renderer

    def counting_renderer(*args, **kwargs):
        renderer = real_create(*args, **kwargs)
        original = renderer.preprocess
        renderer.preprocess = lambda *a, **k: (draws.append(renderer.budget), original(*a, **k))
        return renderer

    monkeypatch.setattr(app, "create_renderer", counting_renderer)
    return draws


def test_budget_key_and_title(gl_ctx, monkeypatch, capsys):
    from viewer import app

    glfw = _fake_glfw(64, 48)
    monkeypatch.setitem(sys.modules, "glfw", glfw)
    monkeypatch.setattr(app, "create_window", lambda w, h, t: ("window", _Context(gl_ctx, w, h)))
    asset = example_asset(seed=9, strands=40, points=6, sh_degree=1)
    draws = _record_drawn_budgets(app, monkeypatch)
    frames = app.run_viewer(asset, title="cgh view t.cgh", file_size=1234, width=64, height=48,
                            rasterizer="compute", max_frames=4, press=("B", "B"))
    assert frames == 4
    assert "B: splat budget" in capsys.readouterr().out
    # B twice: adaptive -> full -> 1/2 of the 200 Gaussians; the camera rests, so one frame is drawn
    # and the others only presented
    assert draws == [100]
    assert glfw.titles[0].startswith("cgh view t.cgh | ")
    assert "| compute | 100 of 200 Gaussians (50 % of strands) | budget 100 | 0.00 MB |" in glfw.titles[0]
    assert len(set(t.split(" | ", 2)[2] for t in glfw.titles)) == 1


def test_fixed_budget_and_raster(gl_ctx, monkeypatch):
    from viewer import app

    glfw = _fake_glfw(48, 40)
    monkeypatch.setitem(sys.modules, "glfw", glfw)
    ctx = _Context(gl_ctx, 48, 40)
    monkeypatch.setattr(app, "create_window", lambda w, h, t: ("window", ctx))
    asset = example_asset(seed=9, strands=40, points=6, sh_degree=1)
    app.run_viewer(asset, title="v", file_size=0, width=48, height=40, rasterizer="raster", budget=60,
                   max_frames=2)
    assert "| raster | 60 of 200 Gaussians (30 % of strands) | budget 60 |" in glfw.titles[-1]
    image = np.frombuffer(ctx.screen.read(components=3), np.uint8)
    assert image.max() > 40  # hair on the stand-in window


def test_adaptive_budget_while_dragging_full_quality_at_rest(gl_ctx, monkeypatch):
    """Dragging the camera draws a reduced budget once a frame has shown the full one too slow;
    the frame after the camera stops is drawn at full quality, and then nothing is redrawn."""
    from viewer import app, camera_control

    glfw = _fake_glfw(64, 48)
    callbacks = {}
    glfw.set_mouse_button_callback = lambda w, f: callbacks.__setitem__("button", f)
    glfw.set_cursor_pos_callback = lambda w, f: callbacks.__setitem__("move", f)
    polls = iter(range(1000))

    def poll(*_):  # frame n: the left button goes down at 1, the cursor moves at 1-6, the button goes up at 7
        n = next(polls)
        if n == 1:
            callbacks["button"](None, 99, glfw.PRESS, 0)
        if 1 <= n <= 6:
            callbacks["move"](None, 10.0 * n, 0.0)
        if n == 7:
            callbacks["button"](None, 99, glfw.RELEASE, 0)

    glfw.poll_events = glfw.wait_events_timeout = poll
    monkeypatch.setitem(sys.modules, "glfw", glfw)
    monkeypatch.setattr(app, "create_window", lambda w, h, t: ("window", _Context(gl_ctx, w, h)))
    # every frame is far too slow for this target: while moving the budget drops to its floor
    monkeypatch.setattr(camera_control, "TARGET_FRAME_S", 1e-9)
    asset = example_asset(seed=9, strands=64, points=6, sh_degree=1)  # 320 Gaussians, 5 a strand
    draws = _record_drawn_budgets(app, monkeypatch)
    frames = app.run_viewer(asset, title="v", file_size=0, width=64, height=48, rasterizer="compute",
                            max_frames=10)
    assert frames == 10
    floor = int(320 * camera_control.MIN_BUDGET_FRACTION)  # 5 Gaussians: one strand
    # rest (full), the first drag frame (full: nothing learned yet), four drag frames at the floor,
    # then at rest full quality once
    assert draws == [None, None, floor, floor, floor, floor, None]
    assert "| 5 of 320 Gaussians (2 % of strands) | budget adaptive |" in glfw.titles[5]
    assert "| 320 Gaussians | budget adaptive |" in glfw.titles[-1]


def test_paused_clip_draws_once(gl_ctx, monkeypatch):
    """A step key pauses the clip on its next frame: that pose is drawn once, then nothing is redrawn."""
    from tests.viewer.test_viewer_animation import moving_cards
    from viewer import app

    glfw = _fake_glfw(64, 48)
    monkeypatch.setitem(sys.modules, "glfw", glfw)
    monkeypatch.setattr(app, "create_window", lambda w, h, t: ("window", _Context(gl_ctx, w, h)))
    asset = example_asset(seed=9, strands=64, points=6, sh_degree=1)
    draws = _record_drawn_budgets(app, monkeypatch)
    assert app.run_viewer(asset, title="v", file_size=0, width=64, height=48, max_frames=4,
                          animation=moving_cards(asset), press=("RIGHT",)) == 4
    assert draws == [None]
    assert "frame 1/2 (0.08 s, 12 fps) paused" in glfw.titles[-1]


@pytest.mark.parametrize("turn_sh", [True, False])
def test_turn_sh_reaches_the_renderer(gl_ctx, monkeypatch, turn_sh):
    """``cgh view --no-turn-sh`` (``turn_sh=False``) plays the clip with the SH as at rest."""
    from tests.viewer.test_viewer_animation import moving_cards
    from viewer import app

    monkeypatch.setitem(sys.modules, "glfw", _fake_glfw(64, 48))
    monkeypatch.setattr(app, "create_window", lambda w, h, t: ("window", _Context(gl_ctx, w, h)))
    turns = []  # whether each renderer made decodes SH turns
    real_create = app.create_renderer

    def create(*args, **kwargs):
        renderer = real_create(*args, **kwargs)
        turns.append(renderer.scene.geometry.turn is not None)
        return renderer

    monkeypatch.setattr(app, "create_renderer", create)
    asset = example_asset(seed=9, strands=64, points=6, sh_degree=1)
    assert app.run_viewer(asset, title="v", file_size=0, width=64, height=48, max_frames=1,
                          animation=moving_cards(asset), turn_sh=turn_sh) == 1
    assert turns == [turn_sh]


def test_ctrl_drag_turns_the_live_head(gl_ctx, monkeypatch):
    """With --simulate every frame steps the solver and is drawn; ctrl-drag turns the head's target and
    leaves the camera where it was."""
    from viewer import app

    glfw = _fake_glfw(64, 48)
    callbacks = {}
    glfw.set_mouse_button_callback = lambda w, f: callbacks.__setitem__("button", f)
    glfw.set_cursor_pos_callback = lambda w, f: callbacks.__setitem__("move", f)
    polls = iter(range(1000))

    def poll(*_):  # ctrl + left button down at 1, the cursor moves right at 1-3
        n = next(polls)
        if n == 1:
            callbacks["button"](None, 99, glfw.PRESS, glfw.MOD_CONTROL)
        if 1 <= n <= 3:
            callbacks["move"](None, 10.0 * n, 0.0)

    glfw.poll_events = glfw.wait_events_timeout = poll
    monkeypatch.setitem(sys.modules, "glfw", glfw)
    monkeypatch.setattr(app, "create_window", lambda w, h, t: ("window", _Context(gl_ctx, w, h)))
    heads = []

    class Recorded(app.LiveSimulation):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            heads.append(self)

    monkeypatch.setattr(app, "LiveSimulation", Recorded)
    asset = example_asset(seed=9, strands=64, points=6, sh_degree=1)
    draws = _record_drawn_budgets(app, monkeypatch)
    cams, real_draw = [], app._draw

    def draw(renderer, camera, settings, budget):
        cams.append(camera.world_to_camera)
        return real_draw(renderer, camera, settings, budget)

    monkeypatch.setattr(app, "_draw", draw)
    assert app.run_viewer(asset, title="v", file_size=0, width=64, height=48, max_frames=5, simulate=True) == 5
    assert len(draws) == 5
    rotation = heads[0].target[0]
    assert np.degrees(np.arccos((np.trace(rotation) - 1) / 2)) == pytest.approx(20 * 0.3)  # 20 pixels right
    assert all(np.array_equal(c, cams[0]) for c in cams)
    assert "simulation live" in glfw.titles[-1]


def test_ctrl_drag_is_the_time_slider(gl_ctx, monkeypatch):
    """With a clip, ctrl-drag pauses at the time the pointer's x gives across the window's width."""
    from tests.viewer.test_viewer_animation import moving_cards
    from viewer import app

    glfw = _fake_glfw(65, 48)
    callbacks = {}
    glfw.set_mouse_button_callback = lambda w, f: callbacks.__setitem__("button", f)
    glfw.set_cursor_pos_callback = lambda w, f: callbacks.__setitem__("move", f)
    polls = iter(range(1000))

    def poll(*_):  # the pointer at x = 20, ctrl + left button down, dragged to the middle, then released
        n = next(polls)
        if n == 0:
            callbacks["move"](None, 20.0, 5.0)
            callbacks["button"](None, 99, glfw.PRESS, glfw.MOD_CONTROL)
        if n == 1:
            callbacks["move"](None, 32.0, 5.0)
            callbacks["button"](None, 99, glfw.RELEASE, glfw.MOD_CONTROL)

    glfw.poll_events = glfw.wait_events_timeout = poll
    monkeypatch.setitem(sys.modules, "glfw", glfw)
    monkeypatch.setattr(app, "create_window", lambda w, h, t: ("window", _Context(gl_ctx, w, h)))
    asset = example_asset(seed=9, strands=64, points=6, sh_degree=1)
    draws = _record_drawn_budgets(app, monkeypatch)
    assert app.run_viewer(asset, title="v", file_size=0, width=65, height=48, max_frames=4,
                          animation=moving_cards(asset, frames=5)) == 4
    assert "frame 1/4" in glfw.titles[0] and "paused" in glfw.titles[0]  # x = 20 of 64: 1.25 of 4 frames
    assert "frame 2/4" in glfw.titles[-1] and "paused" in glfw.titles[-1]
    assert len(draws) == 2  # the orbit did not move: only the two poses were drawn
