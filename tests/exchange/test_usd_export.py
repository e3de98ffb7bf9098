"""USD export of assets and strands, read back with usd-core."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pxr", reason="usd-core is needed for the USD tests (pip install 'cghair[usd]')")
from pxr import Usd, UsdGeom  # noqa: E402

from cghair_format.errors import CghError  # noqa: E402
from cghair_format.examples import example_asset  # noqa: E402
from cghair_format.exchange.cgh_strands import strand_colors  # noqa: E402
from cghair_format.exchange.usd_export import export_usd  # noqa: E402
from cghair_format.gaussians import SH_C0, decode_gaussians, decode_points, strand_sh  # noqa: E402
from cghair_format.geometry import card_mesh  # noqa: E402


@pytest.fixture(scope="module")
def asset():
    a = example_asset(seed=3, sh_degree=2)
    a.meters_per_unit = 0.01
    a.up_axis = "Z"
    return a


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usdz"])
def test_asset_export_all(tmp_path, asset, ext):
    path = tmp_path / f"a{ext}"
    export_usd(path, asset=asset, curves=True, cards=True, gaussians=True)
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    root = stage.GetDefaultPrim()
    # GroomAPI is Unreal's schema, unknown to usd-core: it is in the apiSchemas list op, not the registry
    assert root.GetPath() == "/Hair" and "GroomAPI" in root.GetMetadata("apiSchemas").GetAddedOrExplicitItems()

    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Hair/Strands"))
    assert curves.GetTypeAttr().Get() == "linear"
    pts = decode_points(asset)
    np.testing.assert_array_equal(np.asarray(curves.GetPointsAttr().Get()), pts.reshape(-1, 3))
    assert list(curves.GetCurveVertexCountsAttr().Get()) == [asset.points_per_strand] * asset.n_strands
    np.testing.assert_allclose(np.asarray(curves.GetWidthsAttr().Get()), 2 * asset.thickness, rtol=1e-6)
    pv = UsdGeom.PrimvarsAPI(curves.GetPrim())
    color = np.asarray(pv.GetPrimvar("displayColor").Get())
    np.testing.assert_allclose(color, strand_colors(asset).reshape(-1, 3), atol=1e-6)
    # band 0 only: the first point of each strand has its first Gaussian's DC colour
    dc = np.clip(SH_C0 * strand_sh(asset)[:, 0, 0, :] + 0.5, 0, 1)
    np.testing.assert_allclose(color.reshape(asset.n_strands, -1, 3)[:, 0], dc, atol=1e-6)
    assert pv.GetPrimvar("displayColor").GetInterpolation() == "vertex"
    assert len(pv.GetPrimvar("displayOpacity").Get()) == pts.size // 3
    np.testing.assert_array_equal(np.asarray(pv.GetPrimvar("groom_color").Get()), color)
    groups = np.asarray(pv.GetPrimvar("groom_group_id").Get())
    np.testing.assert_array_equal(groups, asset.cards.group[asset.strand_card])
    assert list(pv.GetPrimvar("groom_guide").Get()) == [0] * asset.n_strands
    assert (pv.GetPrimvar("groom_version_major").Get(), pv.GetPrimvar("groom_version_minor").Get()) == (1, 5)

    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Hair/Cards"))
    m = card_mesh(asset.cards)
    np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get()), m.vertices)
    np.testing.assert_array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), m.triangles.reshape(-1))
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st")
    np.testing.assert_array_equal(np.asarray(st.Get()), m.uvs)

    splat = stage.GetPrimAtPath("/Hair/Gaussians")
    assert splat.GetTypeName() == "ParticleField3DGaussianSplat"
    g = decode_gaussians(asset)
    np.testing.assert_array_equal(np.asarray(splat.GetAttribute("positions").Get()), g.means)
    quats = splat.GetAttribute("orientations").Get()
    wxyz = np.array([[q.GetReal(), *q.GetImaginary()] for q in quats])
    np.testing.assert_allclose(wxyz, g.rotations, atol=1e-7)
    np.testing.assert_array_equal(np.asarray(splat.GetAttribute("scales").Get()), g.scales)
    np.testing.assert_array_equal(np.asarray(splat.GetAttribute("opacities").Get()), g.opacities)
    assert splat.GetAttribute("radiance:sphericalHarmonicsDegree").Get() == 2
    sh = np.asarray(splat.GetAttribute("radiance:sphericalHarmonicsCoefficients").Get())
    np.testing.assert_array_equal(sh, g.sh.reshape(-1, 3))


def test_optional_strand_ids_and_root_uvs(tmp_path):
    a = example_asset(seed=2)
    a.root_uv = np.random.default_rng(0).random((a.n_strands, 2)).astype(np.float32)
    a.strand_ids = np.arange(a.n_strands, dtype=np.uint32)[::-1].copy()
    path = tmp_path / "a.usda"
    export_usd(path, asset=a.validate())
    stage = Usd.Stage.Open(str(path))  # keep the stage alive while its prims are used
    pv = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/Hair/Strands"))
    np.testing.assert_array_equal(np.asarray(pv.GetPrimvar("groom_root_uv").Get()), a.root_uv)
    np.testing.assert_array_equal(np.asarray(pv.GetPrimvar("groom_id").Get()), a.strand_ids)
    assert pv.GetPrimvar("groom_id").GetInterpolation() == "uniform"


def test_strands_export_and_options(tmp_path, small_strands):
    path = tmp_path / "s.usda"
    export_usd(path, strands=small_strands, groom=False)
    stage = Usd.Stage.Open(str(path))
    assert not stage.GetDefaultPrim().HasAuthoredMetadata("apiSchemas")
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Hair/Strands"))
    assert not UsdGeom.PrimvarsAPI(curves.GetPrim()).GetPrimvar("groom_color")
    with pytest.raises(CghError, match="only for a .cgh asset"):
        export_usd(tmp_path / "x.usda", strands=small_strands, cards=True)
    with pytest.raises(CghError, match="writes .usd"):
        export_usd(tmp_path / "x.abc", strands=small_strands)
    with pytest.raises(CghError, match="nothing to export"):
        export_usd(tmp_path / "x.usda", asset=example_asset(), curves=False)


def test_missing_usd_core_names_the_extra(tmp_path, monkeypatch, small_strands):
    import sys

    from cghair_format.errors import MissingDependencyError
    from cghair_format.exchange import load_strands

    monkeypatch.setitem(sys.modules, "pxr.Usd", None)  # import pxr.Usd now raises ImportError
    with pytest.raises(MissingDependencyError, match=r"cghair\[usd\]"):
        export_usd(tmp_path / "x.usda", strands=small_strands)
    (tmp_path / "y.usda").write_text("#usda 1.0\n")
    with pytest.raises(MissingDependencyError, match="usd-core"):
        load_strands(tmp_path / "y.usda")
