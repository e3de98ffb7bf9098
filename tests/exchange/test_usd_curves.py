"""USD BasisCurves import: cubic bases, wraps, primvar interpolations, transforms and stage metadata."""

from __future__ import annotations

import numpy as np
import pytest

pxr = pytest.importorskip("pxr", reason="usd-core is needed for the USD tests (pip install 'cghair[usd]')")
from pxr import Gf, Sdf, Usd, UsdGeom, Vt  # noqa: E402

from cghair_format.exchange import StrandFileError, load_strands  # noqa: E402
from cghair_format.exchange._common import linear_to_srgb  # noqa: E402
from cghair_format.exchange.usd_curves import CUBIC_SAMPLES  # noqa: E402


def _stage(path, pts, counts, ctype="linear", basis="bspline", wrap="nonperiodic"):
    stage = Usd.Stage.CreateNew(str(path))
    curves = UsdGeom.BasisCurves.Define(stage, "/C")
    curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(pts, np.float32)))
    curves.CreateCurveVertexCountsAttr(list(counts))
    curves.CreateTypeAttr(ctype)
    curves.CreateBasisAttr(basis)
    curves.CreateWrapAttr(wrap)
    return stage, curves


def test_linear_with_transform_and_metadata(tmp_path):
    path = tmp_path / "t.usda"
    pts = np.arange(15, dtype=np.float32).reshape(5, 3)
    stage, curves = _stage(path, pts, [2, 3])
    UsdGeom.Xformable(curves).AddTranslateOp().Set(Gf.Vec3d(10, 0, 0))
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.Save()
    s = load_strands(path)
    assert list(s.point_counts) == [2, 3]
    np.testing.assert_allclose(s.points, pts + [10, 0, 0])
    assert (s.meters_per_unit, s.up_axis) == (0.01, "Z")


def test_unauthored_metadata_keeps_defaults(tmp_path):
    path = tmp_path / "t.usda"
    stage, _ = _stage(path, np.zeros((2, 3)), [2])
    stage.Save()
    s = load_strands(path)
    assert (s.meters_per_unit, s.up_axis) == (1.0, "Y")


@pytest.mark.parametrize("basis,wrap", [("bspline", "pinned"), ("catmullRom", "pinned"),
                                        ("bspline", "nonperiodic"), ("catmullRom", "nonperiodic")])
def test_cubic_on_a_straight_line(tmp_path, basis, wrap):
    path = tmp_path / "c.usda"
    cv = np.stack([np.arange(6.0), np.zeros(6), np.zeros(6)], 1)
    stage, _ = _stage(path, cv, [6], "cubic", basis, wrap)
    stage.Save()
    s = load_strands(path)
    nseg = 5 if wrap == "pinned" else 3
    assert s.count == 1 and s.point_counts[0] == nseg * CUBIC_SAMPLES + 1
    np.testing.assert_allclose(s.points[:, 1:], 0, atol=1e-6)
    assert (np.diff(s.points[:, 0]) > 0).all()
    if wrap == "pinned":  # pinned curves start and end at the end control points
        np.testing.assert_allclose(s.points[[0, -1], 0], [0, 5], atol=1e-6)
    elif basis == "catmullRom":  # Catmull-Rom interpolates its inner control points
        np.testing.assert_allclose(s.points[[0, -1], 0], [1, 4], atol=1e-6)


def test_bezier_hits_segment_ends(tmp_path):
    path = tmp_path / "b.usda"
    rng = np.random.default_rng(0)
    cv = rng.normal(size=(7, 3))
    stage, _ = _stage(path, cv, [7], "cubic", "bezier")
    stage.Save()
    s = load_strands(path)
    assert s.point_counts[0] == 2 * CUBIC_SAMPLES + 1
    np.testing.assert_allclose(s.points[[0, CUBIC_SAMPLES, -1]], cv[[0, 3, 6]], atol=1e-5)


def test_bad_bezier_vertex_count(tmp_path):
    path = tmp_path / "b.usda"
    stage, _ = _stage(path, np.zeros((6, 3)), [6], "cubic", "bezier")
    stage.Save()
    with pytest.raises(StrandFileError, match="bezier curve cannot have 6 vertices"):
        load_strands(path)


@pytest.mark.parametrize("interp", ["constant", "uniform", "varying", "vertex", "faceVarying"])
def test_primvar_interpolations_linear(tmp_path, interp):
    path = tmp_path / "p.usda"
    stage, curves = _stage(path, np.arange(15.0).reshape(5, 3), [2, 3])
    n = {"constant": 1, "uniform": 2}.get(interp, 5)
    widths = np.arange(1, n + 1, dtype=np.float32)
    curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(widths))
    curves.SetWidthsInterpolation(interp)
    colors = np.linspace(0, 1, 3 * n).reshape(n, 3).astype(np.float32)
    UsdGeom.PrimvarsAPI(curves.GetPrim()).CreatePrimvar(
        "displayColor", Sdf.ValueTypeNames.Color3fArray, interp).Set(Vt.Vec3fArray.FromNumpy(colors))
    stage.Save()
    s = load_strands(path)
    expect = {"constant": [0, 0, 0, 0, 0], "uniform": [0, 0, 1, 1, 1]}.get(interp, [0, 1, 2, 3, 4])
    np.testing.assert_allclose(s.widths, widths[expect])
    np.testing.assert_allclose(s.colors, linear_to_srgb(colors[expect]), atol=1e-7)  # USD colours are linear


def test_cubic_varying_and_vertex_primvars(tmp_path):
    path = tmp_path / "p.usda"
    cv = np.stack([np.arange(6.0), np.zeros(6), np.zeros(6)], 1)
    stage, curves = _stage(path, cv, [6], "cubic", "bspline", "pinned")
    curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(np.arange(6, dtype=np.float32)))  # varying: nseg + 1
    curves.SetWidthsInterpolation("varying")
    UsdGeom.PrimvarsAPI(curves.GetPrim()).CreatePrimvar(
        "groom_color", Sdf.ValueTypeNames.Color3fArray, "vertex").Set(
        Vt.Vec3fArray.FromNumpy(np.full((6, 3), 0.25, np.float32)))
    stage.Save()
    s = load_strands(path)
    np.testing.assert_allclose(s.widths, np.linspace(0, 5, 5 * CUBIC_SAMPLES + 1), atol=1e-6)
    np.testing.assert_allclose(s.colors, linear_to_srgb(0.25), atol=1e-6)  # groom_color when displayColor is absent


def test_wrong_primvar_size(tmp_path):
    path = tmp_path / "p.usda"
    stage, curves = _stage(path, np.zeros((5, 3)), [2, 3])
    curves.CreateWidthsAttr(Vt.FloatArray([1.0, 2.0, 3.0]))
    curves.SetWidthsInterpolation("vertex")
    stage.Save()
    with pytest.raises(StrandFileError, match="vertex primvar needs 5 values"):
        load_strands(path)


def test_stage_without_curves_and_truncated_files(tmp_path, small_strands):
    from cghair_format.exchange import save_strands

    path = tmp_path / "empty.usda"
    Usd.Stage.CreateNew(str(path)).Save()
    with pytest.raises(StrandFileError, match="no BasisCurves"):
        load_strands(path)
    for ext in (".usda", ".usdc", ".usdz"):
        good = tmp_path / f"good{ext}"
        save_strands(small_strands, good)
        data = good.read_bytes()
        for cut in (10, len(data) // 2):
            bad = tmp_path / f"cut{cut}{ext}"
            bad.write_bytes(data[:cut])
            with pytest.raises(StrandFileError, match=f"cut{cut}"):
                load_strands(bad)
