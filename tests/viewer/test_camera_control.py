"""Camera controller math and key handling of the interactive viewer (pure logic, no window)."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.camera_control import (
    BUDGET_FRACTIONS,
    MAX_ELEVATION,
    MIN_BUDGET_FRACTION,
    MIN_DISTANCE,
    ORBIT_DEG_PER_PIXEL,
    TARGET_FRAME_S,
    ZOOM_PER_STEP,
    BudgetControl,
    OrbitController,
    ViewerState,
)


def _ctl(**kw) -> OrbitController:
    args = {"target": (0.1, 0.2, 0.3), "distance": 2.0, "azimuth": 10.0, "elevation": 5.0}
    args.update(kw)
    return OrbitController(**args)


def test_camera_sits_on_the_orbit_and_looks_at_target():
    ctl = _ctl()
    cam = ctl.camera(64, 48)
    assert np.linalg.norm(cam.center - ctl.target) == pytest.approx(2.0)
    uv, z = cam.project(ctl.target[None])
    np.testing.assert_allclose(uv[0], (32.0, 24.0), atol=1e-9)
    assert z[0] == pytest.approx(2.0)


def test_orbit_changes_angles_and_clamps_elevation():
    ctl = _ctl()
    ctl.orbit(10, 0)
    assert ctl.azimuth == pytest.approx(10.0 - 10 * ORBIT_DEG_PER_PIXEL)
    ctl.orbit(0, 1e6)
    assert ctl.elevation == MAX_ELEVATION
    ctl.orbit(0, -1e6)
    assert ctl.elevation == -MAX_ELEVATION
    assert np.linalg.norm(ctl.camera(8, 8).center - ctl.target) == pytest.approx(2.0)


def test_zoom_scales_distance_and_keeps_a_minimum():
    ctl = _ctl()
    ctl.zoom(2)
    assert ctl.distance == pytest.approx(2.0 * ZOOM_PER_STEP ** 2)
    ctl.zoom(-2)
    assert ctl.distance == pytest.approx(2.0)
    ctl.zoom(1e4)
    assert ctl.distance == MIN_DISTANCE


def test_pan_moves_the_scene_with_the_pointer():
    """A world point at the target follows a drag of (dx, dy) pixels on screen."""
    ctl = _ctl(elevation=0.0)
    point = ctl.target.copy()
    ctl.pan(12, -7, 480)
    uv, _ = ctl.camera(640, 480).project(point[None])
    np.testing.assert_allclose(uv[0], (320 + 12, 240 - 7), atol=1e-6)


def test_fly_moves_along_view_axes_and_keeps_orientation():
    ctl = _ctl()
    before = ctl.camera(8, 8)
    ctl.fly(forward=1.0, right=0.0, up=0.0, seconds=0.5)
    after = ctl.camera(8, 8)
    fwd = before.world_to_camera[2, :3]
    np.testing.assert_allclose(after.center - before.center, fwd * 0.5 * 0.5 * 2.0, atol=1e-9)
    np.testing.assert_allclose(after.world_to_camera[:3, :3], before.world_to_camera[:3, :3], atol=1e-12)
    ctl.fly(0, 1, 0, 1.0)
    right = before.world_to_camera[0, :3]
    assert np.dot(ctl.camera(8, 8).center - after.center, right) > 0


def test_reset_restores_the_home_view():
    ctl = _ctl()
    ctl.orbit(50, 20)
    ctl.zoom(3)
    ctl.pan(5, 5, 100)
    ctl.reset()
    assert (ctl.azimuth, ctl.elevation, ctl.distance) == (10.0, 5.0, 2.0)
    np.testing.assert_allclose(ctl.target, (0.1, 0.2, 0.3))


def test_framing_sees_the_whole_box():
    lo, hi = np.array([-1.0, -2.0, -0.5]), np.array([1.0, 0.5, 0.5])
    for up in ("Y", "Z"):
        ctl = OrbitController.framing(lo, hi, up_axis=up, azimuth=33.0, elevation=20.0)
        cam = ctl.camera(100, 100)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        uv, depth = cam.project(corners)
        assert (depth > 0).all()
        assert ((uv >= 0) & (uv <= 100)).all()


def test_keys_toggle_settings_and_return_actions():
    state = ViewerState(_ctl(), max_sh_degree=2)
    assert state.press("c") is None and state.settings.show_cards
    state.press("C")
    assert not state.settings.show_cards
    state.press("L")
    state.press("G")
    assert state.settings.show_strands and state.settings.color_by_group
    state.press("3")
    assert state.settings.sh_degree == 2  # clamped to the file's degree
    state.press("0")
    assert state.settings.sh_degree == 0
    state.press("=")
    state.press("=")
    assert state.settings.splat_scale == pytest.approx(1.5625)
    state.press("-")
    assert state.settings.splat_scale == pytest.approx(1.25)
    state.press("[")
    state.press("]")
    assert state.settings.splat_scale == pytest.approx(1.25)
    assert state.press("P") == "screenshot"
    assert state.press("ESCAPE") == "quit"
    assert state.press("F7") is None  # unmapped keys do nothing
    state.controller.orbit(30, 0)
    state.press("R")
    assert state.settings.splat_scale == 1.0 and state.settings.sh_degree is None
    assert state.controller.azimuth == 10.0
    assert "SH file" in state.status() and "strands" in state.status()
    assert state.settings.turn_sh and "not turned" not in state.status()
    state.press("T")
    assert not state.settings.turn_sh and "SH not turned" in state.status()


def test_held_keys_fly():
    state = ViewerState(_ctl())
    start = state.controller.target.copy()
    state.fly({"W", "D"}, 0.1)
    assert not np.allclose(state.controller.target, start)
    moved = state.controller.target.copy()
    state.fly({"W", "S"}, 0.1)  # opposite keys cancel
    np.testing.assert_allclose(state.controller.target, moved)


def test_key_b_cycles_budgets():
    state = ViewerState(_ctl())
    assert state.press("b") == "budget"
    control = BudgetControl(1_000_000)
    seen = [control.label()]
    for _ in range(2 + len(BUDGET_FRACTIONS)):
        control.cycle()
        seen.append(control.label())
    assert seen == ["adaptive", "full", "500,000", "250,000", "125,000", "62,500", "adaptive"]
    assert [control.budget(moving) for moving in (False, True)] == [None, None]  # nothing learned yet
    control.mode = 250_000
    assert control.budget(False) == control.budget(True) == 250_000
    control.mode = "full"
    assert control.budget(True) is None


def test_command_line_budget_joins_the_cycle():
    control = BudgetControl(1_000_000, fixed=300_000)
    assert control.label() == "300,000" and control.budget(False) == 300_000
    assert control.modes() == ["adaptive", "full", 500_000, 300_000, 250_000, 125_000, 62_500]
    control.cycle()
    assert control.label() == "250,000"
    assert BudgetControl(1000, fixed=5000).budget(False) == 1000  # at most every Gaussian


def test_adaptive_budget_follows_frame_time_while_moving():
    control = BudgetControl(2_500_000)
    for _ in range(30):  # frames take 4 us per Gaussian drawn: the target needs 75,000 Gaussians
        budget = control.budget(moving=True) or control.total
        control.record(budget * 4e-6, budget, moving=True)
    assert control.budget(moving=True) == pytest.approx(TARGET_FRAME_S / 4e-6, rel=0.01)
    assert control.budget(moving=False) is None  # full quality at rest
    control.record(100.0, 2_500_000, moving=False)  # a full frame at rest teaches nothing
    assert control.budget(moving=True) == pytest.approx(TARGET_FRAME_S / 4e-6, rel=0.01)
    for _ in range(30):  # a very slow machine: the floor
        control.record(1000.0, control.budget(moving=True), moving=True)
    assert control.budget(moving=True) == int(2_500_000 * MIN_BUDGET_FRACTION)
    for _ in range(60):  # a fast one: every Gaussian
        control.record(1e-3, control.budget(moving=True) or control.total, moving=True)
    assert control.budget(moving=True) is None


def test_window_title_says_what_is_drawn():
    from viewer.app import window_title

    title = window_title("cgh view hair.cgh", 2.5, "compute | 500,000 of 2,500,000 Gaussians (20 % of strands)",
                         "adaptive", 3_400_000, "SH file, scale 1.00")
    assert title == ("cgh view hair.cgh | 2.5 fps | compute | 500,000 of 2,500,000 Gaussians (20 % of strands) | "
                     "budget adaptive | 3.40 MB | SH file, scale 1.00")
