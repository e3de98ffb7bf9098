"""The viewer's toggles: SH degree, splat scale, colour by group, overlays, hidden splats."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from PIL import Image

from cghair_format import decode_gaussians
from cghair_format.camera import Camera
from cghair_format.examples import example_asset
from viewer.frame import ViewSettings
from viewer.renderer import Renderer, default_sort_mode, projection_matrix

splatter = pytest.importorskip("training.splatter", reason="the reference splatter needs torch")
pytestmark = pytest.mark.gl


@pytest.fixture
def scene(gl_ctx):
    asset = example_asset(seed=4, strands=80, points=10, sh_degree=3, groups=3)
    renderer = Renderer.from_asset(gl_ctx, asset, rasterizer="raster")
    lo, hi = renderer.bounds
    cam = Camera.orbit((lo + hi) / 2, 0.45, 30.0, 10.0, 64, 64)
    yield asset, renderer, cam
    renderer.release()


def _psnr(a, b):
    return 10 * np.log10(1.0 / max(float(np.mean((a - b) ** 2)), 1e-20))


def test_sh_degree_truncates_like_the_reference(scene):
    asset, renderer, cam = scene
    g = decode_gaussians(asset)
    full = renderer.render(cam)
    for degree in (0, 1, 2):
        got = renderer.render(cam, ViewSettings(sh_degree=degree))
        cut = dataclasses.replace(g, sh=g.sh[:, :(degree + 1) ** 2].copy())
        want = splatter.render_gaussians(cut, cam)["rgb"]
        assert _psnr(got[..., :3], want) > 35
        assert _psnr(got[..., :3], full[..., :3]) < 80  # the degree changed the picture


def test_splat_scale_scales_gaussians(scene):
    asset, renderer, cam = scene
    g = decode_gaussians(asset)
    got = renderer.render(cam, ViewSettings(splat_scale=2.0))
    want = splatter.render_gaussians(dataclasses.replace(g, scales=g.scales * 2), cam)
    assert _psnr(got[..., :3], want["rgb"]) > 35
    assert got[..., 3].sum() > renderer.render(cam)[..., 3].sum()


def test_color_by_group_uses_one_colour_per_group(scene):
    asset, renderer, cam = scene
    img = renderer.render(cam, ViewSettings(color_by_group=True))
    assert not np.allclose(img, renderer.render(cam))
    renderer.preprocess(cam, ViewSettings(color_by_group=True))
    raster = renderer.rasterizers["raster"]  # the buffers the preprocess writes for the raster path
    colour = np.frombuffer(raster.color.read(), np.float32).reshape(-1, 4)[:, :3]
    radius = np.frombuffer(raster.center.read(), np.float32).reshape(-1, 4)[:, 3]
    group = np.repeat(asset.cards.group[asset.strand_card], asset.points_per_strand - 1)
    seen = {}
    for gid in np.unique(group):
        visible = (group == gid) & (radius > 0)
        assert visible.any()
        c = colour[visible]
        np.testing.assert_array_equal(c, np.broadcast_to(c[0], c.shape))  # one colour per group
        seen[int(gid)] = tuple(c[0])
    assert len(set(seen.values())) == len(seen)  # and different groups differ


def test_overlays_draw_lines_and_cards(scene):
    _, renderer, cam = scene
    empty = ViewSettings(hide_splats=True, background=(0.0, 0.0, 0.0))
    none = renderer.render(cam, empty)
    assert none[..., :3].max() == 0.0
    lines = renderer.render(cam, dataclasses.replace(empty, show_strands=True))
    cards = renderer.render(cam, dataclasses.replace(empty, show_cards=True))
    assert (lines[..., :3].max(axis=-1) > 0.1).sum() > 50
    assert (cards[..., :3].max(axis=-1) > 0.05).sum() > (lines[..., :3].max(axis=-1) > 0.1).sum()
    both = renderer.render(cam, ViewSettings(show_cards=True, show_strands=True, color_by_group=True))
    assert both[..., 3].max() > 0


def test_projection_matrix_matches_the_camera():
    cam = Camera(50, 40, fx=60.0, fy=55.0, cx=20.0, cy=22.0, world_to_camera=np.eye(4))
    p = np.array([0.1, -0.2, 1.5])
    clip = projection_matrix(cam) @ np.append(p, 1.0)
    ndc = clip[:3] / clip[3]
    uv, _ = cam.project(p[None])
    np.testing.assert_allclose((ndc[:2] + 1) / 2 * (50, 40), uv[0])
    assert -1 < ndc[2] < 1


def test_sort_mode_choice(gl_ctx):
    assert default_sort_mode(gl_ctx) in ("gpu", "cpu")
    with pytest.raises(ValueError, match="sort must be one of"):
        Renderer.from_gaussians(gl_ctx, decode_gaussians(example_asset()), sort="quick")
    with pytest.raises(ValueError, match="primitive must be one of"):
        Renderer.from_gaussians(gl_ctx, decode_gaussians(example_asset()), primitive="points")


def test_bare_baselines_cover_the_same_quads(scene, gl_ctx):
    from viewer.bench import Baselines

    _, renderer, cam = scene
    renderer.render(cam)  # a raster frame: preprocess, sort, gather, draw
    baselines = Baselines(renderer)
    target = renderer.accum(cam.width, cam.height)
    coverage = []
    for draw in (baselines.draw_sorted, baselines.draw_records):
        draw(target, cam.width, cam.height)
        alpha = np.frombuffer(target.texture.read(), np.float32).reshape(cam.height, cam.width, 4)[..., 3]
        coverage.append(alpha > 0)
    baselines.release()
    assert coverage[0].sum() > 100
    np.testing.assert_array_equal(coverage[0], coverage[1])  # same quads, two data paths


def test_z_up_asset_renders_like_its_y_up_twin(gl_ctx, tmp_path):
    """``cgh render``'s orbit follows the file's up axis: a Z-up copy (rotated +90 degrees about x)
    looks the same as the Y-up original from the same azimuth and elevation (SH degree 0, so
    colour does not depend on world directions)."""
    from viewer.render_jobs import RenderJob, render_job

    asset = example_asset(seed=12, strands=50, points=10, sh_degree=0)
    rot = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # (x, y, z) -> (x, -z, y)
    twin = dataclasses.replace(asset, cards=dataclasses.replace(
        asset.cards, spine=(asset.cards.spine @ rot.T).astype(np.float32),
        normal=(asset.cards.normal @ rot.T).astype(np.float32)), up_axis="Z")
    job = RenderJob(width=48, height=48, azimuth=40.0, elevation=25.0)
    images = []
    for a, name in ((asset, "y.png"), (twin, "z.png")):
        render_job(a, job, tmp_path / name, ctx=gl_ctx)
        images.append(np.asarray(Image.open(tmp_path / name)).astype(int))
    assert images[0].max() > 40
    assert np.abs(images[0] - images[1]).max() <= 1


def test_resizing_keeps_few_targets(scene):
    _, renderer, cam = scene
    for size in (16, 24, 32, 40):
        small = Camera.orbit(renderer.scene.bounds[0], 0.5, 0.0, 0.0, size, size)
        assert renderer.render(small).shape == (size, size, 4)
    assert len(renderer._targets) <= 2


def test_fallback_toggles_match_the_gpu_path(scene, gl_ctx):
    from viewer.fallback import FallbackRenderer

    asset, renderer, cam = scene
    fallback = FallbackRenderer.from_asset(gl_ctx, asset)
    for settings in (ViewSettings(color_by_group=True), ViewSettings(sh_degree=1),
                     ViewSettings(splat_scale=2.0, background=(0.5, 0.5, 0.5))):
        # numpy computes in float64, the GPU in float32
        np.testing.assert_allclose(fallback.render(cam, settings), renderer.render(cam, settings), atol=2e-4)
    stages = []  # numpy projects and sorts in its preprocess; the gather uploads the records
    fallback.frame(cam, stage=lambda name, fn: (stages.append(name), fn())[1])
    assert stages == ["preprocess", "gather", "draw"] and fallback.drawn == fallback.visible > 0
    fallback.release()
