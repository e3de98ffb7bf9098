"""Real hair models (../shared/data/hair): strands -> cards -> .cgh, rendered by the viewer and by
the reference splatter. Skipped with a message where the shared folder is absent."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hairdata import load_hair

import cghair_format
from cghair_format import decode_gaussians
from cghair_format.camera import Camera
from viewer.decode import read_gaussians
from viewer.frame import ViewSettings
from viewer.renderer import Renderer

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def real_asset(tmp_path_factory):
    pytest.importorskip("sklearn", reason="the card builder needs the 'cards' extra")
    from cghair_format.cards.build import build_cards
    strands = load_hair("Bangs_100.hair")
    asset = build_cards(strands, n_cards=12, n_groups=4, points=12, progress=False, sh_degree=2).asset
    path = tmp_path_factory.mktemp("real") / "bangs.cgh"
    cghair_format.write(asset, path)
    return cghair_format.read(path)  # through the file format, as users load it


def test_real_hair_gpu_decode(gl_ctx, real_asset):
    renderer = Renderer.from_asset(gl_ctx, real_asset)
    got, want = read_gaussians(renderer.scene), decode_gaussians(real_asset)
    scale = float(np.abs(want.means).max())
    np.testing.assert_allclose(got.means, want.means, atol=4e-7 * scale)
    np.testing.assert_allclose(got.sh, want.sh, atol=2e-5)
    renderer.release()


def test_real_hair_matches_reference(gl_ctx, real_asset):
    splatter = pytest.importorskip("training.splatter", reason="the reference splatter needs torch")
    renderer = Renderer.from_asset(gl_ctx, real_asset)
    lo, hi = renderer.scene.bounds
    radius = float(np.linalg.norm(hi - lo)) / 2
    g = decode_gaussians(real_asset)
    for azimuth in (0.0, 120.0):
        cam = Camera.orbit((lo + hi) / 2, 2.6 * radius, azimuth, 10.0, 96, 96, real_asset.up_axis)
        got = renderer.render(cam, ViewSettings(background=(1.0, 1.0, 1.0)))
        want = splatter.render_gaussians(g, cam, (1.0, 1.0, 1.0))
        assert want["alpha"].max() > 0.3
        mse = float(np.mean((got[..., :3] - want["rgb"]) ** 2))
        assert mse == 0 or 10 * math.log10(1 / mse) >= 35.0
    renderer.release()
