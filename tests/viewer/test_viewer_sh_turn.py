"""Appearance follows in the viewer: an animated frame's SH turn with their segments on the GPU as
:func:`cghair_format.animation.frame_gaussians` turns them on the CPU (``turn_sh=True``), and
``turn_sh=False`` leaves them as at rest."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cghair_format.animation import frame_gaussians, segment_rotations
from cghair_format.examples import example_asset
from cghair_format.gaussians import eval_sh
from tests.viewer.test_viewer_animation import _camera, moving_cards
from viewer.frame import ViewSettings
from viewer.renderer import Renderer

splatter = pytest.importorskip("training.splatter", reason="the reference splatter needs torch")
pytestmark = pytest.mark.gl

# Rotations: a few float32 quaternion products, rotations and normalisations of unit values, each a few
# ulps (6e-8): measured 7e-7 at most; the turns tested reach 0.67 from the identity.
ROTATION_TOL = 2e-6
# Colours: the GPU's SH (decoded in float32) differ from the CPU's by up to 2e-5 a coefficient
# (tests/viewer/test_gpu_decode.py), and sum_lm |Y_lm(v)| <= sum_l (2l + 1) / sqrt(4 pi) = 4.5 to degree
# 3, so 9e-5; the turned view direction (2e-6) adds far less (measured: 6e-7 in all). Not turning
# differs by up to 0.8 here (0.2 on average).
COLOUR_TOL = 1e-4
TURNED_APART = 100 * COLOUR_TOL


@pytest.fixture(scope="module")
def asset():
    return example_asset(seed=3, strands=48, points=9, sh_degree=3)


def _turns(renderer: Renderer) -> np.ndarray:
    """The segment rotations the GPU decoded, as matrices ``[G, 3, 3]``."""
    import torch

    q = np.frombuffer(renderer.scene.geometry.turn.turns.read(), np.float32).reshape(-1, 4)[:renderer.count]
    return splatter.quat_to_rotmat(torch.from_numpy(q.astype(np.float64))).numpy()


def _colours(renderer: Renderer, camera) -> tuple[np.ndarray, np.ndarray]:
    """Each Gaussian's colour from the preprocess (raster path's buffers) and which are on screen."""
    renderer.preprocess(camera, ViewSettings(), "raster")
    raster = renderer.rasterizer_named("raster")
    colour = np.frombuffer(raster.color.read(), np.float32).reshape(-1, 4)[:renderer.count, :3]
    keys = np.frombuffer(renderer.keys.read(), np.uint32)[:renderer.count]
    return colour, keys != 0xFFFFFFFF


def _cpu_colours(gaussians, camera) -> np.ndarray:
    dirs = gaussians.means.astype(np.float64) - np.asarray(camera.center, np.float64)
    return eval_sh(gaussians.sh.astype(np.float64), dirs / np.linalg.norm(dirs, axis=1, keepdims=True))


def test_gpu_segment_turns_match_segment_rotations(gl_ctx, asset):
    animation = moving_cards(asset)
    renderer = Renderer.from_asset(gl_ctx, asset, animated=True)
    try:
        for f in (2, 1, 0):
            renderer.move_cards(animation.cards(asset.cards, f))
            want = segment_rotations(asset, animation, f).reshape(-1, 3, 3)
            np.testing.assert_allclose(_turns(renderer), want, atol=ROTATION_TOL)
        assert np.abs(segment_rotations(asset, animation, 2) - np.eye(3)).max() > 0.5  # the test can fail
    finally:
        renderer.release()


@pytest.mark.parametrize("budget", [None, 120])
def test_turned_colours_match_frame_gaussians(gl_ctx, asset, budget):
    """The preprocess's colours of a moved frame against the CPU's turned SH evaluated from the same
    camera; a budget decodes (and turns) only the strands it draws."""
    animation, cam = moving_cards(asset), _camera(asset)
    renderer = Renderer.from_asset(gl_ctx, asset, animated=True, budget=budget)
    try:
        renderer.move_cards(animation.cards(asset.cards, 2))
        renderer.budget = None  # the colours of every Gaussian at once (the rest decoded first)
        renderer.frame(cam)
        got, seen = _colours(renderer, cam)
        assert seen.sum() > renderer.count // 2
        turned = _cpu_colours(frame_gaussians(asset, animation, 2, turn_sh=True), cam)
        unturned = _cpu_colours(frame_gaussians(asset, animation, 2, turn_sh=False), cam)
        assert np.abs(got[seen] - turned[seen]).max() < COLOUR_TOL
        assert np.abs(got[seen] - unturned[seen]).max() > TURNED_APART
    finally:
        renderer.release()


def test_no_turn_sh_leaves_the_colours_as_at_rest(gl_ctx, asset):
    animation, cam = moving_cards(asset), _camera(asset)
    renderer = Renderer.from_asset(gl_ctx, asset, animated=True, turn_sh=False)
    try:
        assert renderer.scene.geometry.turn is None
        renderer.move_cards(animation.cards(asset.cards, 2))
        got, seen = _colours(renderer, cam)
        unturned = _cpu_colours(frame_gaussians(asset, animation, 2, turn_sh=False), cam)
        assert np.abs(got[seen] - unturned[seen]).max() < COLOUR_TOL
    finally:
        renderer.release()


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((np.asarray(a, np.float64) - b) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(1.0 / mse)


@pytest.mark.parametrize("rasterizer", ["compute", "raster"])
def test_turned_frame_renders_as_the_reference(gl_ctx, asset, rasterizer):
    """The whole image: the viewer's turned frame against the reference splatter on frame_gaussians'
    turned Gaussians (as tests/viewer/test_splat_vs_reference.py: >= 75 dB compute, 90 dB raster), far
    above the same reference against the unturned Gaussians."""
    animation, cam = moving_cards(asset), _camera(asset, 96, 72)
    renderer = Renderer.from_asset(gl_ctx, asset, animated=True, rasterizer=rasterizer)
    try:
        renderer.move_cards(animation.cards(asset.cards, 2))
        got = renderer.render(cam)[..., :3]
        want = splatter.render_gaussians(frame_gaussians(asset, animation, 2, turn_sh=True), cam)["rgb"]
        unturned = splatter.render_gaussians(frame_gaussians(asset, animation, 2, turn_sh=False), cam)["rgb"]
        floor = 75.0 if rasterizer == "compute" else 90.0
        assert _psnr(got, want) >= floor
        assert _psnr(unturned, want) < floor - 30
    finally:
        renderer.release()


def test_static_frame_in_an_animated_renderer_skips_the_turns(gl_ctx, asset):
    """``ViewSettings(turn_sh=False)`` (key T; the benchmark's static frame) draws the SH as at rest, like
    a renderer made with ``turn_sh=False``, bit for bit."""
    animation, cam = moving_cards(asset), _camera(asset)
    turning = Renderer.from_asset(gl_ctx, asset, animated=True)
    plain = Renderer.from_asset(gl_ctx, asset, animated=True, turn_sh=False)
    try:
        for r in (turning, plain):
            r.move_cards(animation.cards(asset.cards, 2))
        turned = turning.render(cam)
        np.testing.assert_array_equal(turning.render(cam, ViewSettings(turn_sh=False)), plain.render(cam))
        assert not np.array_equal(turned, plain.render(cam))
    finally:
        turning.release()
        plain.release()
