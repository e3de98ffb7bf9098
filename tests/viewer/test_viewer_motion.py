"""Where the viewer's moving cards come from (viewer/motion.py), without OpenGL: frame ranges, the clip
player's keys and real-time clock, and the live simulation against the solver's own run."""

from __future__ import annotations

import numpy as np
import pytest

import cghair_format
from cghair_format import Cards
from cghair_format.animation import simulated_animation
from cghair_format.errors import CghError
from cghair_format.examples import example_asset
from viewer.motion import ClipPlayer, LiveSimulation, file_animation, parse_frames


@pytest.fixture(scope="module")
def asset():
    return example_asset(seed=8, strands=60, points=10, sh_degree=1)


@pytest.fixture(scope="module")
def nod(asset):
    return simulated_animation(asset, "nod", 8, 24.0)


@pytest.mark.parametrize(("text", "want"), [("2:5", [2, 3, 4]), (":3", [0, 1, 2]), ("7:", [7, 8, 9]),
                                             ("4", [4]), ("-1", [9]), ("-2:", [8, 9]), (":", list(range(10)))])
def test_parse_frames(text, want):
    assert list(parse_frames(text, 10)) == want


@pytest.mark.parametrize("text", ["a:b", "1:2:3", "12", "5:2", ""])
def test_parse_frames_rejects(text):
    with pytest.raises(CghError, match="--frames"):
        parse_frames(text, 10)


def test_clip_player_keys_and_clock(asset, nod):
    player = ClipPlayer(nod, asset.cards)
    first = player.advance(0.0)
    np.testing.assert_array_equal(first.spine, nod.spine[0])
    assert player.advance(0.01) is None  # less than a frame at 24 fps: nothing new to upload
    cards = player.advance(2.5 / 24)  # real time: frames are skipped, not slowed down
    assert player.frame == 2 and np.array_equal(cards.spine, nod.spine[2])
    player.advance(6 / 24)
    assert player.frame == 0  # looped
    assert player.press("SPACE") and not player.playing and not player.active
    assert player.advance(1.0) is None  # paused
    assert player.press("LEFT") and player.frame == 7
    assert player.press("HOME") and player.frame == 0
    assert player.press("END") and player.frame == 7
    assert player.press("PAGE_UP") and player.frame == 0
    assert not player.press("C")  # not a playback key: the camera's
    player.press("SPACE")
    player.seek(0.5)
    assert player.frame == 4 and not player.playing  # round(0.5 * 7): the time slider pauses
    player.seek(2.0)
    assert player.frame == 7
    assert "frame 7/7" in player.status() and "paused" in player.status()


def test_clip_player_range_and_validation(asset, nod):
    player = ClipPlayer(nod, asset.cards, range(3, 6))
    assert player.frame == 3
    player.press("LEFT")
    assert player.frame == 5
    c = asset.cards
    with pytest.raises(CghError, match="animation frames"):
        ClipPlayer(nod, Cards(c.spine[:4], c.normal[:4], c.half_width[:4], c.group[:4]))


def test_live_simulation_starts_as_the_solver_does(asset, nod):
    """Settled as drive.simulate settles; the head held still, it follows the same steps as the 'still'
    motion of the solver; turned by the mouse, the roots ride the head rigidly."""
    live = LiveSimulation(asset, fps=24.0)
    np.testing.assert_allclose(live.advance().spine, nod.spine[0], atol=1e-6)
    still = simulated_animation(asset, "still", 3, 24.0)
    for f in (1, 2):
        np.testing.assert_allclose(live.advance().spine, still.spine[f], atol=1e-5)
    live.turn(10.0, 0.0, np.array([1.0, 0.0, 0.0]))
    cards = live.advance()
    rotation, translation = live.rotation, live.translation
    assert np.degrees(np.arccos((np.trace(rotation) - 1) / 2)) == pytest.approx(10.0)
    np.testing.assert_allclose(cards.spine[:, 0], asset.cards.spine[:, 0] @ rotation.T + translation, atol=1e-5)
    normals = np.linalg.norm(cards.normal, axis=-1)
    np.testing.assert_allclose(normals, 1.0, atol=1e-5)
    assert live.press("SPACE") and live.advance() is None  # paused
    assert "simulation paused" in live.status()


def test_live_head_moves_are_bounded(asset):
    live = LiveSimulation(asset)
    live.turn(1000.0, 0.0, np.array([1.0, 0.0, 0.0]))
    angle = np.degrees(np.arccos((np.trace(live.target[0]) - 1) / 2))
    assert angle == pytest.approx(15.0)  # MAX_TURN_DEG a call
    live.move(np.array([10.0, 0.0, 0.0]))
    assert np.linalg.norm(live.target[1] - (live.centre - live.target[0] @ live.centre)) == pytest.approx(live.radius)
    live.reset()
    np.testing.assert_array_equal(live.target[0], np.eye(3))


def test_file_animation_until_the_format_reads_them(tmp_path, monkeypatch, nod):
    monkeypatch.delattr(cghair_format, "read_animation", raising=False)
    assert file_animation(str(tmp_path / "any.cgh")) is None
    monkeypatch.setattr(cghair_format, "read_animation", lambda path: nod, raising=False)
    assert file_animation(str(tmp_path / "any.cgh")) is nod
