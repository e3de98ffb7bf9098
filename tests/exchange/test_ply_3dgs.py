"""3DGS PLY: the INRIA layout (channel-major f_rest, logit opacity, log scales, wxyz rotation)."""

from __future__ import annotations

import numpy as np
import pytest

from cghair_format.examples import example_asset
from cghair_format.exchange import StrandFileError
from cghair_format.exchange._ply import read_ply, write_ply
from cghair_format.exchange.ply_3dgs import read_3dgs_ply, write_3dgs_ply
from cghair_format.gaussians import Gaussians, decode_gaussians


def _gaussians(n=6, deg=3, seed=0) -> Gaussians:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return Gaussians(rng.normal(size=(n, 3)).astype(np.float32), q.astype(np.float32),
                     rng.uniform(0.01, 0.1, (n, 3)).astype(np.float32), rng.uniform(0.05, 0.95, n).astype(np.float32),
                     rng.normal(size=(n, (deg + 1) ** 2, 3)).astype(np.float32))


def test_layout_matches_the_inria_convention(tmp_path):
    g = _gaussians()
    path = tmp_path / "g.ply"
    write_3dgs_ply(g, path, up="y")  # as stored: no turn
    v = read_ply(path).elements["vertex"].data
    names = list(v)
    assert names[:9] == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    assert names[9:54] == [f"f_rest_{i}" for i in range(45)]
    assert names[54:] == ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    # channel-major: f_rest_0..14 are red coefficients 1..15, f_rest_15.. green, f_rest_30.. blue
    np.testing.assert_array_equal(v["f_rest_0"], g.sh[:, 1, 0])
    np.testing.assert_array_equal(v["f_rest_14"], g.sh[:, 15, 0])
    np.testing.assert_array_equal(v["f_rest_15"], g.sh[:, 1, 1])
    np.testing.assert_array_equal(v["f_rest_30"], g.sh[:, 1, 2])
    np.testing.assert_allclose(1 / (1 + np.exp(-v["opacity"])), g.opacities, rtol=1e-5)
    np.testing.assert_allclose(np.exp(v["scale_1"]), g.scales[:, 1], rtol=1e-5)
    np.testing.assert_array_equal(v["rot_0"], g.rotations[:, 0])  # w first


def test_roundtrip_asset_gaussians(tmp_path):
    g = decode_gaussians(example_asset(sh_degree=1))
    path = tmp_path / "g.ply"
    write_3dgs_ply(g, path)  # y down, as 3DGS viewers expect: a half turn about x, exact in float
    back = read_3dgs_ply(path, up="Y")
    assert back.count == g.count and back.sh_degree == 3  # padded to degree 3 for viewers
    np.testing.assert_array_equal(back.sh[:, :4], g.sh)
    assert not back.sh[:, 4:].any()
    np.testing.assert_array_equal(back.means, g.means)
    np.testing.assert_allclose(back.scales, g.scales, rtol=1e-6)
    np.testing.assert_allclose(back.opacities, g.opacities, atol=2e-6)
    same_sign = np.sign((back.rotations * g.rotations).sum(1))[:, None]  # q and -q: one rotation
    np.testing.assert_allclose(back.rotations * same_sign, g.rotations, atol=1e-6)
    raw = read_3dgs_ply(path)  # as stored: y and z negated
    np.testing.assert_array_equal(raw.means, g.means * np.array([1, -1, -1], np.float32))
    write_3dgs_ply(g, path, pad_to_degree=0)
    assert read_3dgs_ply(path).sh_degree == 1


def test_rejects_non_3dgs_ply(tmp_path):
    path = tmp_path / "p.ply"
    write_ply(path, [("vertex", {"x": np.zeros(2, np.float32), "y": np.zeros(2, np.float32),
                                 "z": np.zeros(2, np.float32)})])
    with pytest.raises(StrandFileError, match="not a 3DGS PLY"):
        read_3dgs_ply(path)
    good = tmp_path / "g.ply"
    write_3dgs_ply(_gaussians(), good)
    data = good.read_bytes()
    bad = tmp_path / "cut.ply"
    bad.write_bytes(data[: len(data) - 10])
    with pytest.raises(StrandFileError, match="truncated"):
        read_3dgs_ply(bad)


def test_an_independent_ply_reader_opens_it(tmp_path):
    """trimesh's PLY reader (not ours) sees every Gaussian and every 3DGS property."""
    trimesh = pytest.importorskip("trimesh")
    g = _gaussians(n=50, deg=3, seed=4)
    path = tmp_path / "g.ply"
    write_3dgs_ply(g, path, up="y")
    cloud = trimesh.load(path)
    np.testing.assert_array_equal(np.asarray(cloud.vertices, np.float32), g.means)
    raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
    np.testing.assert_array_equal(raw["f_rest_44"], g.sh[:, 15, 2])
    np.testing.assert_array_equal(raw["rot_3"], g.rotations[:, 3])


def test_strand_loader_names_a_splat_file(tmp_path):
    from cghair_format.exchange import load_strands

    path = tmp_path / "g.ply"
    write_3dgs_ply(_gaussians(), path)
    with pytest.raises(StrandFileError, match="Gaussian splat PLY, not strands"):
        load_strands(path)


@pytest.mark.parametrize("source_up,up", [("Y", "-y"), ("Y", "z"), ("Z", "-y"), ("Z", "y"), ("Z", "z")])
def test_orientation_turns_means_rotations_and_sh_together(tmp_path, source_up, up):
    """Turned to another up axis and scaled, every Gaussian shows the same colour from the turned
    view direction, its covariance is the turned one, and the header says the up axis and units."""
    from scipy.spatial.transform import Rotation

    from cghair_format.exchange.ply_3dgs import AA_COMMENT, orientation
    from cghair_format.gaussians import eval_sh

    g = _gaussians(n=40, deg=3, seed=5)
    path = tmp_path / "g.ply"
    write_3dgs_ply(g, path, source_up=source_up, up=up, scale=100.0, meters_per_unit=1.0)
    comments = read_ply(path).comments
    assert f"up {up}" in comments and "units 0.01 m" in comments and AA_COMMENT in comments
    out = read_3dgs_ply(path)
    r = orientation(source_up, up)
    world_up = {"Y": [0, 1, 0], "Z": [0, 0, 1]}[source_up]
    assert np.allclose(r @ world_up, {"-y": [0, -1, 0], "y": [0, 1, 0], "z": [0, 0, 1]}[up])
    np.testing.assert_allclose(out.means, 100 * g.means @ r.T, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(out.scales, 100 * g.scales, rtol=1e-5)
    def cov(q, s):
        m = Rotation.from_quat(np.asarray(q, np.float64)[:, [1, 2, 3, 0]]).as_matrix()
        return np.einsum("gij,gj,gkj->gik", m, s.astype(np.float64) ** 2, m)

    turned = np.einsum("ij,gjk,lk->gil", r, cov(g.rotations, 100 * g.scales), r)
    np.testing.assert_allclose(cov(out.rotations, out.scales), turned, rtol=0, atol=1e-5 * np.abs(turned).max())
    d = np.random.default_rng(1).normal(size=(g.count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(eval_sh(out.sh, d @ r.T), eval_sh(g.sh, d), atol=1e-5)
    back = read_3dgs_ply(path, up=source_up)  # the up comment turns it back
    np.testing.assert_allclose(back.means, 100 * g.means, rtol=1e-5, atol=1e-5)


def test_default_ply_is_upright_in_the_colmap_convention(tmp_path):
    """3DGS viewers take y down: the written scalp (roots, up in our y-up asset) has the lowest y."""
    from cghair_format.gaussians import decode_points

    asset = example_asset(seed=1)
    pts = decode_points(asset)
    assert asset.up_axis == "Y" and pts[:, 0, 1].mean() > pts[:, -1, 1].mean()  # roots above tips
    path = tmp_path / "g.ply"
    write_3dgs_ply(decode_gaussians(asset), path)
    means = read_3dgs_ply(path).means.reshape(asset.n_strands, -1, 3)
    assert means[:, 0, 1].mean() < means[:, -1, 1].mean()
    assert "up -y" in read_ply(path).comments
