"""The interactive window under a virtual X server (Xvfb): scripted frames, key presses and a
screenshot that must equal the headless render of the same view. Skipped where Xvfb is absent."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import cghair_format
from cghair_format.examples import example_asset

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def xvfb_display():
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb): the window test needs a display")
    read, write = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                            pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write)
    with os.fdopen(read) as f:
        number = f.readline().strip()
    if not number:
        proc.kill()
        pytest.skip("Xvfb did not start")
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=10)


def _view(display, *args, cwd):
    env = dict(os.environ, DISPLAY=display)
    cmd = [sys.executable, "-m", "cghair_format", "view", *map(str, args)]
    return subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=300)


def _assert_the_screenshot_is_the_headless_render(folder) -> None:
    """The window's one screenshot in ``folder`` against ``folder/headless.png``, the same view rendered
    headless: within the 8-bit rounding of the window's framebuffer."""
    shots = sorted(folder.glob("cgh_view_*.png"))
    assert len(shots) == 1
    window = np.asarray(Image.open(shots[0])).astype(int)
    headless = np.asarray(Image.open(folder / "headless.png")).astype(int)
    assert headless.max() > 40
    assert np.abs(window - headless).max() <= 1


def test_window_screenshot_matches_headless_render(xvfb_display, tmp_path, capsys):
    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=8, strands=60, points=10, sh_degree=1), path)
    done = _view(xvfb_display, path, "--width", 96, "--height", 72, "--frames", 3, "--press", "P",
                 "--screenshots", tmp_path, cwd=tmp_path)
    assert done.returncode == 0, done.stderr

    from cghair_format.cli import main

    assert main(["render", str(path), "-o", str(tmp_path / "headless.png"), "--width", "96", "--height", "72",
                 "--elevation", "0"]) == 0
    _assert_the_screenshot_is_the_headless_render(tmp_path)


def test_window_toggles_run(xvfb_display, tmp_path):
    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=9, strands=30, points=8, sh_degree=2), path)
    done = _view(xvfb_display, path, "--width", 64, "--height", 48, "--frames", 4, "--press", "LCG0=-HRP",
                 "--screenshots", tmp_path, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert len(list(tmp_path.glob("cgh_view_*.png"))) == 1


@pytest.mark.parametrize("args", [["--rasterizer", "compute", "--press", "BBB"], ["--budget", "100", "--press", "B"]])
def test_window_budgets_and_rasterizers_run(xvfb_display, tmp_path, args):
    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=9, strands=30, points=8, sh_degree=2), path)
    done = _view(xvfb_display, path, "--width", 64, "--height", 48, "--frames", 3, *args, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr


PLAY_SCRIPT = """
import sys
import numpy as np
from cghair_format.examples import example_asset
from tests.viewer.test_viewer_animation import moving_cards
from viewer.app import run_viewer
from viewer.camera_control import OrbitController
from viewer.render_jobs import RenderJob, render_job

asset = example_asset(seed=8, strands=60, points=10, sh_degree=1)
animation = moving_cards(asset)
run_viewer(asset, title="play", file_size=0, width=96, height=72, max_frames=3, animation=animation,
           press=("RIGHT", "RIGHT", "P"), screenshot_dir=sys.argv[1])
c = asset.cards
lo = c.spine.reshape(-1, 3).min(axis=0) - c.half_width.max()
hi = c.spine.reshape(-1, 3).max(axis=0) + c.half_width.max()
ctl = OrbitController.framing(lo, hi, asset.up_axis)
job = RenderJob(width=96, height=72, azimuth=ctl.azimuth, elevation=ctl.elevation, distance=ctl.distance,
                target=tuple(ctl.target), frames=range(2, 3))
render_job(asset, job, sys.argv[1] + "/headless.png", animation=animation)
"""


def test_window_plays_an_animation(xvfb_display, tmp_path):
    """Two steps (right arrow, which pauses) show frame 2: the screenshot equals the headless render of
    that frame seen by the same camera, each Gaussian's SH turned with its segment in both."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ, DISPLAY=xvfb_display, PYTHONPATH=root)
    done = subprocess.run([sys.executable, "-c", PLAY_SCRIPT, str(tmp_path)], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    _assert_the_screenshot_is_the_headless_render(tmp_path)


def test_window_simulates_live(xvfb_display, tmp_path):
    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=9, strands=30, points=8, sh_degree=2), path)
    done = _view(xvfb_display, path, "--width", 64, "--height", 48, "--frames", 4, "--simulate",
                 "--press", "SPACE,SPACE,P", "--screenshots", tmp_path, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "ctrl-drag: turn the head" in done.stdout and "Traceback" not in done.stderr
    assert len(list(tmp_path.glob("cgh_view_*.png"))) == 1
