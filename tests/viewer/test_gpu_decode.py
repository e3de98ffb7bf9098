"""The GPU decode reproduces cghair_format.decode_gaussians (numpy) to float32 tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from cghair_format import decode_gaussians, decode_points
from cghair_format.examples import example_asset
from viewer import decode
from viewer.decode import read_gaussians, read_points, upload_asset, upload_gaussians
from viewer.pipeline import Programs

pytestmark = pytest.mark.gl

# float32 on the GPU against numpy's float64 geometry: positions of magnitude ~0.3 agree to a
# few ulps (1e-6); the MLP sums ~20 float32 products of order 1 (1e-5); rotations are
# normalised float32 quaternions (1e-5, looser where a segment is almost antiparallel to +z).
POS_TOL, SH_TOL, ROT_TOL = 2e-6, 2e-5, 2e-5


def _compare(ctx, asset):
    scene = upload_asset(ctx, Programs(ctx), asset)
    try:
        got, want = read_gaussians(scene), decode_gaussians(asset)
        np.testing.assert_allclose(read_points(scene), decode_points(asset), atol=POS_TOL)
        np.testing.assert_allclose(got.means, want.means, atol=POS_TOL)
        np.testing.assert_allclose(got.scales, want.scales, atol=POS_TOL)
        np.testing.assert_allclose(got.rotations, want.rotations, atol=ROT_TOL)
        np.testing.assert_array_equal(got.opacities, want.opacities)
        np.testing.assert_allclose(got.sh, want.sh, atol=SH_TOL)
    finally:
        scene.release()


@pytest.mark.parametrize("sh_degree", [0, 1, 2, 3])
@pytest.mark.parametrize("weight_mode", ["soft", "hard"])
def test_decode_matches_numpy(gl_ctx, sh_degree, weight_mode):
    _compare(gl_ctx, example_asset(seed=sh_degree, sh_degree=sh_degree, weight_mode=weight_mode))


def test_decode_temperature_and_strands_off_card(gl_ctx):
    asset = example_asset(seed=5, strands=40, points=9)
    asset.appearance.temperature = 0.37
    asset.uvd[:5, :, 0] *= 1.2  # past the card's tip: extrapolating barycentrics
    asset.uvd[5:10, :, 1] = -0.3  # left of the left rail
    _compare(gl_ctx, asset)


def test_sh_split_into_chunks(gl_ctx, monkeypatch):
    """A tiny storage-block limit forces many SH chunks; the result must not change."""
    asset = example_asset(seed=2, strands=50, points=8, sh_degree=2)
    out_bytes = 4 * (asset.points_per_strand - 1) * 9 * 3
    monkeypatch.setattr(decode, "sh_chunk_bytes", lambda ctx: 3 * out_bytes)
    scene = upload_asset(gl_ctx, Programs(gl_ctx), asset)
    try:
        assert len(scene.sh) == 17  # ceil(50 / 3)
        assert sum(c.count for c in scene.sh) == asset.n_gaussians
        np.testing.assert_allclose(read_gaussians(scene).sh, decode_gaussians(asset).sh, atol=SH_TOL)
    finally:
        scene.release()


def test_upload_gaussians_roundtrip(gl_ctx):
    g = decode_gaussians(example_asset(seed=3))
    scene = upload_gaussians(gl_ctx, g)
    try:
        back = read_gaussians(scene)
        for name in ("means", "rotations", "scales", "opacities", "sh"):
            np.testing.assert_array_equal(getattr(back, name), getattr(g, name))
        with pytest.raises(ValueError, match="no strand points"):
            read_points(scene)
    finally:
        scene.release()


def test_too_many_gaussians_is_a_clear_error(gl_ctx, monkeypatch):
    asset = example_asset(strands=20, points=6)  # 100 Gaussians
    monkeypatch.setattr(decode, "block_limit", lambda ctx: 16 * 99)
    with pytest.raises(decode.SceneTooLargeError, match="100 Gaussians.*at most 99"):
        upload_asset(gl_ctx, Programs(gl_ctx), asset)
    with pytest.raises(decode.SceneTooLargeError):
        upload_gaussians(gl_ctx, decode_gaussians(asset))


def test_placeholders_of_a_variable_count_asset_decode_invisible(gl_ctx):
    """The shaders decode all ``S (P-1)`` segments (spec 3's padded arrays); placeholders get opacity 0,
    which preprocessing culls, and the real ones match decode_gaussians."""
    from cghair_format.examples import with_point_counts

    asset = with_point_counts(example_asset(seed=4, strands=30, points=10), seed=1)
    scene = upload_asset(gl_ctx, Programs(gl_ctx), asset)
    try:
        got, want = read_gaussians(scene), decode_gaussians(asset)
        real = asset.real_segments().ravel()
        assert scene.count == len(real) and want.count == int(real.sum()) < len(real)
        assert (got.opacities[~real] == 0).all()
        np.testing.assert_array_equal(got.opacities[real], want.opacities)
        np.testing.assert_allclose(got.means[real], want.means, atol=POS_TOL)
        np.testing.assert_allclose(got.sh[real], want.sh, atol=SH_TOL)
    finally:
        scene.release()
