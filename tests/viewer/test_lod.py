"""Level of detail (viewer/lod.py): a stable, nested subset of strands, compensated, drawn exactly
as the reference splatter draws that subset."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_splat_vs_reference import psnr

from cghair_format import decode_gaussians
from cghair_format.camera import Camera
from cghair_format.examples import example_asset
from viewer import lod as lod_module
from viewer.lod import parse_budget, strand_ranks
from viewer.renderer import Renderer, check_budget

pytestmark = pytest.mark.gl
STRANDS, POINTS = 120, 9  # 8 Gaussians per strand


def test_ranks_are_a_fixed_permutation():
    ranks = strand_ranks(1000)
    assert sorted(ranks.tolist()) == list(range(1000))
    np.testing.assert_array_equal(ranks, strand_ranks(1000))
    assert not np.array_equal(ranks, np.arange(1000))
    # any prefix is spread over the whole index range, not a block of it
    first = np.nonzero(ranks < 100)[0]
    assert np.histogram(first, bins=4, range=(0, 1000))[0].min() >= 15
    np.testing.assert_array_equal(strand_ranks(10), strand_ranks(10))


def test_parse_budget():
    assert parse_budget("250000") == 250_000
    assert parse_budget("250k") == 250_000
    assert parse_budget("2.5M") == 2_500_000
    assert parse_budget("1,000") == 1000
    for bad in ("", "abc", "0", "-3", "nan", "inf", "1e400"):
        with pytest.raises(ValueError):
            parse_budget(bad)
    with pytest.raises(ValueError, match="positive number of Gaussians"):
        check_budget(0)
    with pytest.raises(ValueError, match="positive number of Gaussians"):
        check_budget(2.5)


def _drawn_strands(renderer: Renderer) -> set[int]:
    """The strands the plan sends through the preprocess, from the GPU's list buffer."""
    lists = np.frombuffer(renderer.lod.buffer.read(), np.uint32)
    plan = renderer.lod.plan(renderer.budget)
    segs = renderer.scene.segments
    return {int(s) for base, n, _ in plan.chunks for s in lists[base:base + n // segs]}


@pytest.fixture
def asset():
    return example_asset(seed=3, strands=STRANDS, points=POINTS, sh_degree=2)


def test_budgets_nest_across_chunks(gl_ctx, asset, monkeypatch):
    from viewer import decode

    monkeypatch.setattr(decode, "sh_chunk_bytes", lambda ctx: 7 * 8 * 27 * 4)  # 7 strands a chunk
    renderer = Renderer.from_asset(gl_ctx, asset)
    assert len(renderer.scene.sh) == 18
    ranks = strand_ranks(STRANDS)
    previous: set[int] = set()
    for strands in (1, 5, 17, 60, 119):
        renderer.budget = strands * 8 + 7  # a partial strand is not drawn
        drawn = _drawn_strands(renderer)
        assert drawn == set(np.nonzero(ranks < strands)[0].tolist())
        assert previous <= drawn
        previous = drawn
    renderer.release()


def _compensated_subset(asset, strands: int):
    """The Gaussians of the ``strands`` lowest-rank strands, compensated as viewer/lod.py says."""
    g = decode_gaussians(asset)
    keep = np.repeat(strand_ranks(STRANDS) < strands, POINTS - 1)
    k = STRANDS / strands
    width, power = k ** lod_module.WIDTH_EXPONENT, k ** (1 - lod_module.WIDTH_EXPONENT)
    scales = g.scales[keep].copy()
    scales[:, :2] *= width
    opacities = 1 - (1 - g.opacities[keep].astype(np.float64)) ** power
    return dataclasses.replace(g, means=g.means[keep], rotations=g.rotations[keep], scales=scales,
                               opacities=opacities.astype(np.float32), sh=g.sh[keep])


@pytest.mark.parametrize("rasterizer", ["compute", "raster"])
def test_budget_draws_the_compensated_subset(gl_ctx, asset, rasterizer):
    splatter = pytest.importorskip("training.splatter", reason="the reference splatter needs torch")
    renderer = Renderer.from_asset(gl_ctx, asset, rasterizer=rasterizer, budget=40 * 8)
    lo, hi = renderer.scene.bounds
    cam = Camera.orbit((lo + hi) / 2, 0.45, 30.0, 15.0, 80, 60)
    got = renderer.render(cam)
    assert renderer.drawn == 40 * 8 and renderer.plan.strands == 40
    want = splatter.render_gaussians(_compensated_subset(asset, 40), cam)
    assert want["alpha"].max() > 0.2
    assert min(psnr(got[..., :3], want["rgb"]), psnr(got[..., 3], want["alpha"])) >= 75.0
    renderer.release()


def test_budget_keeps_coverage_and_full_budget_is_exact(gl_ctx, asset):
    renderer = Renderer.from_asset(gl_ctx, asset)
    lo, hi = renderer.scene.bounds
    cam = Camera.orbit((lo + hi) / 2, 0.45, 30.0, 15.0, 80, 60)
    full = renderer.render(cam)
    renderer.budget = renderer.scene.count  # every strand: the full image, no compensation
    np.testing.assert_array_equal(renderer.render(cam), full)
    assert renderer.plan.full
    renderer.budget = renderer.scene.count // 2
    half = renderer.render(cam)
    # the compensation keeps the hair's coverage; dropping half the strands alone loses a lot of it
    assert abs(half[..., 3].mean() / full[..., 3].mean() - 1) < 0.1
    assert "50 % of strands" in renderer.describe() and renderer.frame_rasterizer in renderer.describe()
    renderer.release()
