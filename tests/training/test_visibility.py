"""Blend weights over views, and the Gaussians a file may store less opaque (training/visibility.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from test_native_splat import camera, hair_scene

from cghair_format.examples import example_asset
from training import native_splat, splatter
from training.datasets.types import View
from training.visibility import blend_weights, least_weight, negligible_segments


def _views(*azimuths: float) -> list[View]:
    return [View(camera(40, 30, az), np.zeros((30, 40, 4), np.float32)) for az in azimuths]


@pytest.mark.parametrize("backend", ["native", "reference"])
def test_the_weights_of_a_view_add_up_to_its_alpha(backend):
    """Front to back, the blend weights of a pixel sum to its alpha: summed over Gaussians, the
    weights of every view must give the alpha of all its pixels."""
    means, quats, scales, opac, _ = hair_scene(0)
    views = _views(0.0, 120.0)
    weights = blend_weights(means.numpy(), quats.numpy(), scales.numpy(), opac.numpy(), views, backend)
    render = native_splat.render if backend == "native" else splatter.render
    alpha = sum(float(render(means, quats, scales, opac, torch.zeros(len(opac), 1, 3), v.camera).alpha.sum())
                for v in views)
    assert weights.min() >= 0 and weights.sum() == pytest.approx(alpha, rel=1e-4)
    assert (weights == 0).any() and (weights > 1).any()  # some hidden or off-screen, some on many pixels


def test_a_gaussian_behind_an_opaque_one_is_the_negligible_one():
    wall = [0.0, -0.3, 0.0], [1, 0, 0, 0], [1.5, 1.5, 0.05], 0.99
    behind = [0.0, -0.3, -0.3], [1, 0, 0, 0], [0.1, 0.1, 0.1], 0.9
    means, quats, scales, opac = (np.array(x, np.float32) for x in zip(wall, behind, strict=True))
    weights = blend_weights(means, quats, scales, opac, _views(0.0))
    assert weights[1] < 1e-3 * weights[0]
    assert least_weight(weights, 0.01).tolist() == [False, True]


def test_lowering_the_least_used_changes_each_picture_by_at_most_twice_their_weight():
    """The bound the module rests on: with the Gaussians carrying a tenth of the weight made fully
    transparent, the summed per-pixel change of a view is within twice their weight there times the
    largest colour (plus early termination's 1e-4 a pixel)."""
    means, quats, scales, opac, sh = hair_scene(0, seed=3)
    views = _views(30.0)
    weights = blend_weights(means.numpy(), quats.numpy(), scales.numpy(), opac.numpy(), views)
    low = torch.as_tensor(least_weight(weights, 0.1))
    assert 0.3 < float(low.float().mean()) < 1  # many Gaussians, a tenth of the weight
    cam = views[0].camera
    before = native_splat.render(means, quats, scales, opac, sh, cam).rgb
    after = native_splat.render(means, quats, scales, torch.where(low, 0.0, opac), sh, cam).rgb
    colour = splatter.eval_sh(sh, torch.tensor([[1.0, 0.0, 0.0]]).expand(len(sh), 3)).max()  # (degree 0)
    change = float((after - before).abs().sum(dim=(0, 1)).max())
    assert 0 < change <= 2 * float(colour) * weights[low.numpy()].sum() + 1e-4 * cam.width * cam.height


def test_negligible_segments_are_shaped_like_the_opacities():
    asset = example_asset(0, strands=30, points=10, cards=3, segments=4)
    views = [View(cam, np.zeros((30, 40, 4), np.float32)) for cam in
             (camera(40, 30, az, distance=6.0) for az in (0.0, 90.0, 200.0))]
    marked = negligible_segments(asset, views, 0.2)
    assert marked.shape == asset.opacity.shape and 0 < marked.mean() < 1
    assert not negligible_segments(asset, views, 0.0).any()


def test_budgets_outside_a_share_are_refused():
    for budget in (-0.1, 1.0, 2.0):
        with pytest.raises(ValueError, match=r"in \[0, 1\)"):
            least_weight(np.ones(3), budget)
    assert not least_weight(np.zeros(4), 0.5).any()  # views that see nothing mark nothing
