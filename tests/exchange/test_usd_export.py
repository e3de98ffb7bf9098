"""USD export of assets and strands, read back with usd-core."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pxr", reason="usd-core is needed for the USD tests (pip install 'cghair[usd]')")
from pxr import Usd, UsdGeom, UsdShade  # noqa: E402

from cghair_format.errors import CghError  # noqa: E402
from cghair_format.examples import example_asset  # noqa: E402
from cghair_format.exchange._common import srgb_to_linear  # noqa: E402
from cghair_format.exchange.cgh_strands import strand_colors  # noqa: E402
from cghair_format.exchange.usd_export import card_faces, export_usd  # noqa: E402
from cghair_format.gaussians import SH_C0, decode_gaussians, decode_points, strand_sh  # noqa: E402
from cghair_format.geometry import card_mesh  # noqa: E402


@pytest.fixture(scope="module")
def asset():
    a = example_asset(seed=3, sh_degree=2)
    a.meters_per_unit = 0.01
    a.up_axis = "Z"
    return a


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usdz"])
def test_asset_export_all(tmp_path, asset, ext, capsys):
    path = tmp_path / f"a{ext}"
    export_usd(path, asset=asset, curves=True, cards=True, gaussians=True)
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("cgh: warning: Blender 5.0's USD importer drops /Hair/Gaussians")
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
    # linear, and saying so: the sRGB display colours through the sRGB transfer function
    np.testing.assert_allclose(color, srgb_to_linear(strand_colors(asset).reshape(-1, 3)), atol=1e-6)
    assert pv.GetPrimvar("displayColor").GetAttr().GetColorSpace() == "lin_rec709_scene"
    assert Usd.ColorSpaceAPI(root).GetColorSpaceNameAttr().Get() == "lin_rec709_scene"
    # band 0 only: the first point of each strand has its first Gaussian's DC colour
    dc = np.clip(SH_C0 * strand_sh(asset)[:, 0, 0, :] + 0.5, 0, 1)
    np.testing.assert_allclose(color.reshape(asset.n_strands, -1, 3)[:, 0], srgb_to_linear(dc), atol=1e-6)
    # a preview surface reads displayColor
    material = UsdShade.MaterialBindingAPI(curves.GetPrim()).ComputeBoundMaterial()[0]
    surface = material.ComputeSurfaceSource()[0]
    assert surface.GetIdAttr().Get() == "UsdPreviewSurface"
    reader = surface.GetInput("diffuseColor").GetConnectedSources()[0][0].source
    assert UsdShade.Shader(reader.GetPrim()).GetInput("varname").Get() == "displayColor"
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
    faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    np.testing.assert_array_equal(faces, card_faces(m.triangles))
    normals = np.asarray(mesh.GetNormalsAttr().Get())
    assert normal_agreement(np.asarray(mesh.GetPointsAttr().Get()), faces, normals) > 0.99
    st = np.asarray(UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st").Get())
    assert st.shape == m.uvs.shape and 0 < st.min() and st.max() < 1
    # the card material: the atlas PNG beside the file (inside a .usdz) as colour and opacity
    material = UsdShade.MaterialBindingAPI(mesh.GetPrim()).ComputeBoundMaterial()[0]
    surface = material.ComputeSurfaceSource()[0]
    tex = UsdShade.Shader(surface.GetInput("opacity").GetConnectedSources()[0][0].source.GetPrim())
    assert tex.GetIdAttr().Get() == "UsdUVTexture"
    assert tex.GetInput("file").Get().path == "./a_cards.png"
    assert (tmp_path / "a_cards.png").exists() == (ext != ".usdz")
    assert surface.GetInput("diffuseColor").GetConnectedSources()[0][0].sourceName == "rgb"

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
    points = UsdGeom.Points(stage.GetPrimAtPath("/Hair/GaussianPoints"))
    np.testing.assert_array_equal(np.asarray(points.GetPointsAttr().Get()), g.means)
    np.testing.assert_allclose(np.asarray(points.GetWidthsAttr().Get()), 2 * g.scales.min(1), rtol=1e-6)
    rgb = UsdGeom.PrimvarsAPI(points.GetPrim()).GetPrimvar("displayColor")
    np.testing.assert_allclose(np.asarray(rgb.Get()), srgb_to_linear(np.clip(SH_C0 * g.sh[:, 0] + 0.5, 0, 1)),
                               atol=1e-6)


def normal_agreement(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray) -> float:
    """Share of triangles whose winding (right-hand rule) faces the same way as their stored normals."""
    v = vertices.astype(np.float64)
    face_n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    return float(np.mean((face_n * normals[faces].astype(np.float64).sum(1)).sum(1) > 0))


@pytest.mark.slow
def test_real_card_normals_agree_with_winding(tmp_path):
    """Cards built from a real model (Bangs_100.hair): stored normals and winding agree (before the
    fix 1 % of faces did, so Cycles shaded the cards' back faces black)."""
    from hairdata import hair_path

    from cghair_format.cards import build_cards
    from cghair_format.exchange import load_strands

    asset = build_cards(load_strands(hair_path("Bangs_100.hair")), n_cards=40, n_groups=8, points=24,
                        progress=False).asset
    path = tmp_path / "bangs.usdc"
    export_usd(path, asset=asset, curves=False, cards=True)
    stage = Usd.Stage.Open(str(path))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Hair/Cards"))
    faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    vertices, normals = np.asarray(mesh.GetPointsAttr().Get()), np.asarray(mesh.GetNormalsAttr().Get())
    assert normal_agreement(vertices, faces, normals) > 0.98
    assert normal_agreement(vertices, faces[:, [0, 2, 1]], normals) < 0.02  # the old winding


def test_scale_keeps_real_size(tmp_path, asset):
    path = tmp_path / "cm.usda"
    export_usd(path, asset=asset, cards=True, gaussians=True, scale=100)
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(asset.meters_per_unit / 100)
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Hair/Strands"))
    np.testing.assert_allclose(np.asarray(curves.GetPointsAttr().Get()), 100 * decode_points(asset).reshape(-1, 3),
                               rtol=1e-6)
    np.testing.assert_allclose(np.asarray(curves.GetWidthsAttr().Get()), 200 * asset.thickness, rtol=1e-6)
    cards = UsdGeom.Mesh(stage.GetPrimAtPath("/Hair/Cards"))
    np.testing.assert_allclose(np.asarray(cards.GetPointsAttr().Get()), 100 * card_mesh(asset.cards).vertices,
                               rtol=1e-6)
    g = decode_gaussians(asset)
    splat = stage.GetPrimAtPath("/Hair/Gaussians")
    np.testing.assert_allclose(np.asarray(splat.GetAttribute("scales").Get()), 100 * g.scales, rtol=1e-6)
    with pytest.raises(CghError, match="positive"):
        export_usd(path, asset=asset, scale=0)


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
    assert "GroomAPI" not in stage.GetDefaultPrim().GetMetadata("apiSchemas").GetAddedOrExplicitItems()
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
