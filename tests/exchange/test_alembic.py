"""Our Alembic groom writer (``cghair_format.exchange.alembic`` over ``_ogawa``).

Two checks: Blender 5.0's Alembic importer (the real Alembic library, in a subprocess) reads
the curves, points and widths; and the independent reader in ``abc_reader.py`` checks the
layout and every groom attribute, which Blender 5.0 does not import for curves (its own
Alembic export and import of a curves object drop generic attributes too).
"""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from abc_reader import Archive
from hairdata import hair_path

from cghair_format.errors import CghError
from cghair_format.examples import example_asset
from cghair_format.exchange import load_strands
from cghair_format.exchange._common import srgb_to_linear
from cghair_format.exchange._ogawa import Compound, Object, Values, write_archive
from cghair_format.exchange.alembic import _geom_param, card_polymesh, export_groom, write_groom
from cghair_format.exchange.blender import BlenderNotFoundError, find_blender_python
from cghair_format.exchange.cgh_strands import strands_from_asset
from cghair_format.geometry import card_mesh
from cghair_format.strands import Strands

BLENDER_SCRIPT = r"""
import json, sys
import bpy
import numpy as np

path, out = sys.argv[-2:]
bpy.ops.wm.read_factory_settings(use_empty=True)
result = bpy.ops.wm.alembic_import(filepath=path)
report = {"result": sorted(result), "objects": {o.name: o.type for o in bpy.data.objects}}
curves = [o for o in bpy.data.objects if o.type == "CURVES"]
if curves:
    o, d = curves[0], curves[0].data
    pos = np.empty(len(d.points) * 3, np.float32)
    d.attributes["position"].data.foreach_get("vector", pos)
    arrays = {"position": pos.reshape(-1, 3), "world": np.array(o.matrix_world, np.float64),
              "sizes": np.array([c.points_length for c in d.curves], np.int64)}
    if "radius" in d.attributes:
        rad = np.empty(len(d.points), np.float32)
        d.attributes["radius"].data.foreach_get("value", rad)
        arrays["radius"] = rad
    np.savez(out, **arrays)
    report.update(curves=len(d.curves), points=len(d.points),
                  attributes={a.name: [a.domain, a.data_type] for a in d.attributes})
meshes = [o for o in bpy.data.objects if o.type == "MESH"]
if meshes:
    m = meshes[0].data
    n = len(m.vertices)
    co = np.empty(n * 3, np.float32)
    m.vertices.foreach_get("co", co)
    normals = np.empty(len(m.polygons) * 3, np.float32)
    m.polygons.foreach_get("normal", normals)
    corners = np.empty(len(m.loops), np.int32)
    m.loops.foreach_get("vertex_index", corners)
    mesh = {"co": co.reshape(-1, 3), "face_normals": normals.reshape(-1, 3), "corners": corners,
            "world": np.array(meshes[0].matrix_world, np.float64)}
    for a in m.attributes:
        if a.data_type in ("FLOAT_COLOR", "BYTE_COLOR", "FLOAT2") and not a.name.startswith("."):
            field = {"FLOAT_COLOR": "color", "BYTE_COLOR": "color_srgb", "FLOAT2": "vector"}[a.data_type]
            width = 2 if field == "vector" else 4
            vals = np.empty(len(a.data) * width, np.float32)
            a.data.foreach_get(field, vals)
            mesh["attr_" + a.name] = vals.reshape(-1, width)
    np.savez(out.replace(".npz", "_mesh.npz"), **mesh)
    report["mesh"] = {"vertices": n, "polygons": len(m.polygons), "uv_layers": [uv.name for uv in m.uv_layers],
                      "attributes": {a.name: [a.domain, a.data_type] for a in m.attributes}}
print("CGH_REPORT " + json.dumps(report))
"""
Y_UP_TO_Z_UP = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)  # Blender's import rotation


def blender_import(abc, tmp_path) -> tuple[dict, dict]:
    try:
        python = find_blender_python()
    except BlenderNotFoundError as exc:
        pytest.fail(f"{exc}. Deselect this test with -m 'not blender'.")
    out = tmp_path / "blender.npz"
    proc = subprocess.run([python, "-c", BLENDER_SCRIPT, str(abc), str(out)], capture_output=True, text=True,
                          timeout=300)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("CGH_REPORT ")]
    assert proc.returncode == 0 and lines, f"Blender failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    report = json.loads(lines[-1][len("CGH_REPORT "):])
    arrays = {}
    for npz in (out, tmp_path / "blender_mesh.npz"):
        if npz.exists():
            arrays.update(np.load(npz))
    return report, arrays


def small_strands(up: str = "Y") -> Strands:
    rng = np.random.default_rng(3)
    counts = rng.integers(2, 9, 30)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    return Strands(rng.normal(size=(n, 3)).astype(np.float32), offsets, rng.random((n, 3)).astype(np.float32),
                   rng.uniform(1e-4, 1e-3, n).astype(np.float32), meters_per_unit=0.01, up_axis=up,
                   root_uv=rng.random((30, 2)).astype(np.float32))


def groom_props(path):
    a = Archive(path)
    curves = a.top.children["Strands"].children["StrandsShape"]
    return a, curves, curves.props[".geom"].props


def test_layout_and_groom_attributes(tmp_path):
    s = small_strands()
    path = tmp_path / "g.abc"
    group, ids = np.arange(30) % 3, np.arange(30) * 7 + 1
    write_groom(path, s, scale=100, group=group, strand_ids=ids)
    a, curves, geom = groom_props(path)
    assert a.frozen and a.version == 1 and a.abc_version == 0 and a.library_version >= 9999
    assert a.metadata["_ai_Application"].startswith("cghair ") and "_ai_AlembicVersion" in a.metadata
    # the default time sampling: one sample, 1 s per cycle, starting at 0
    assert a.time_samplings_raw == np.array([1], "<u4").tobytes() + np.array([1.0], "<f8").tobytes() + \
        np.array([1], "<u4").tobytes() + np.array([0.0], "<f8").tobytes()
    hair = a.top.children["Strands"]
    assert hair.metadata["schema"] == "AbcGeom_Xform_v3" and hair.props[".xform"].props[".inherits"].values[0, 0]
    assert curves.metadata == {"schema": "AbcGeom_Curve_v2", "schemaObjTitle": "AbcGeom_Curve_v2:.geom"}
    assert curves.props[".geom"].metadata["schema"] == "AbcGeom_Curve_v2"
    k = 0.01 * 100  # metres per unit times the scale
    np.testing.assert_array_equal(geom["P"].values, s.points * np.float32(k))
    assert geom["P"].metadata == {"geoScope": "vtx", "interpretation": "point"}
    np.testing.assert_array_equal(geom["nVertices"].values[:, 0], s.point_counts)
    assert list(geom["curveBasisAndType"].values[0]) == [1, 0, 0, 0]  # linear, non-periodic
    np.testing.assert_allclose(geom[".selfBnds"].values[0], np.r_[s.points.min(0), s.points.max(0)] * k, rtol=1e-6)
    np.testing.assert_array_equal(geom["width"].values[:, 0], s.widths * np.float32(k))
    arb = geom[".arbGeomParams"].props
    expect = {"groom_color": ("vtx", "float32_t", 3), "groom_width": ("vtx", "float32_t", 1),
              "groom_group_id": ("uni", "int32_t", 1), "groom_guide": ("uni", "int16_t", 1),
              "groom_id": ("uni", "int32_t", 1), "groom_root_uv": ("uni", "float32_t", 2),
              "groom_version_major": ("con", "int16_t", 1), "groom_version_minor": ("con", "int16_t", 1)}
    assert set(arb) == set(expect)
    for name, (scope, pod, extent) in expect.items():
        md = arb[name].metadata
        assert (md["geoScope"], md["podName"], int(md["podExtent"]), md["isGeomParam"]) == (scope, pod, extent, "true")
        assert arb[name].kind == "array" and arb[name].samples == 1
    assert arb["groom_color"].metadata["interpretation"] == "rgb"
    np.testing.assert_array_equal(arb["groom_color"].values, srgb_to_linear(s.colors))  # linear, as Unreal reads it
    np.testing.assert_array_equal(arb["groom_root_uv"].values, s.root_uv)
    np.testing.assert_array_equal(arb["groom_group_id"].values[:, 0], group)
    np.testing.assert_array_equal(arb["groom_id"].values[:, 0], ids)
    assert not arb["groom_guide"].values.any()
    assert (arb["groom_version_major"].values[0, 0], arb["groom_version_minor"].values[0, 0]) == (1, 5)


def test_z_up_strands_turn_y_up(tmp_path):
    s = small_strands(up="Z")
    write_groom(tmp_path / "z.abc", s)
    _, _, geom = groom_props(tmp_path / "z.abc")
    p = s.points * np.float32(0.01)
    np.testing.assert_allclose(geom["P"].values, np.stack([p[:, 0], p[:, 2], -p[:, 1]], 1), rtol=1e-6)


def test_strands_without_optional_attributes(tmp_path):
    s = Strands.from_array(np.zeros((4, 3, 3), np.float32) + np.arange(3, dtype=np.float32)[:, None])
    write_groom(tmp_path / "bare.abc", s)
    _, _, geom = groom_props(tmp_path / "bare.abc")
    assert "width" not in geom
    assert set(geom[".arbGeomParams"].props) == {"groom_group_id", "groom_guide", "groom_version_major",
                                                 "groom_version_minor"}


def test_equal_samples_are_stored_once_and_metadata_is_indexed(tmp_path):
    one = Values("a", np.arange(1000, dtype=np.float32), {"geoScope": "vtx"})
    two = Values("b", np.arange(1000, dtype=np.float32), {"geoScope": "vtx"})
    write_archive(tmp_path / "one.abc", [Object("o", {}, [one])], {})
    write_archive(tmp_path / "two.abc", [Object("o", {}, [one, two])], {})
    size = (tmp_path / "two.abc").stat().st_size - (tmp_path / "one.abc").stat().st_size
    assert size < 100  # a header and a group, not another 4000 bytes
    a = Archive(tmp_path / "two.abc")
    assert a.md_table == [{"geoScope": "vtx"}]
    np.testing.assert_array_equal(a.top.children["o"].props["b"].values[:, 0], one.values)


def test_cli_exports_plain_strands(tmp_path, capsys):
    from cghair_format.cli import main
    from cghair_format.exchange import save_strands

    s = small_strands()
    save_strands(s, tmp_path / "in.npz")
    assert main(["export", str(tmp_path / "in.npz"), "-o", str(tmp_path / "x.abc"), "--scale", "2"]) == 0
    assert "warning" not in capsys.readouterr().err
    _, _, geom = groom_props(tmp_path / "x.abc")
    np.testing.assert_array_equal(geom["P"].values, s.points * np.float32(0.01 * 2))
    np.testing.assert_array_equal(geom[".arbGeomParams"].props["groom_color"].values, srgb_to_linear(s.colors))
    assert main(["export", str(tmp_path / "in.npz"), "-o", str(tmp_path / "no" / "x.abc")]) != 0
    assert "cannot write" in capsys.readouterr().err  # the CLI checks the output before any work


def test_unwritable_output_is_a_clear_error(tmp_path):
    with pytest.raises(CghError, match="cannot write the Alembic file"):
        write_groom(tmp_path / "missing" / "g.abc", small_strands())


def test_bad_metadata_leaves_no_file(tmp_path):
    path = tmp_path / "bad.abc"
    with pytest.raises(ValueError, match="metadata"):
        write_archive(path, [Object("o", {"a": "x;y"}, [])], {})
    assert not path.exists()


@pytest.mark.blender
def test_blender_imports_our_groom(tmp_path):
    s = small_strands()
    path = tmp_path / "g.abc"
    write_groom(path, s, scale=100)
    report, got = blender_import(path, tmp_path)
    assert report["result"] == ["FINISHED"] and report["objects"] == {"Strands": "CURVES"}
    assert report["curves"] == s.count and report["points"] == len(s.points)
    assert list(got["sizes"]) == list(s.point_counts)
    expect = s.points.astype(np.float64)  # 0.01 m per unit times 100
    world = got["position"] @ got["world"][:3, :3].T + got["world"][:3, 3]
    np.testing.assert_allclose(world, expect @ Y_UP_TO_Z_UP.T, rtol=0, atol=1e-6 * np.abs(expect).max())
    np.testing.assert_allclose(got["radius"], s.widths / 2, rtol=1e-6)  # Alembic widths are diameters
    # what Blender 5.0 makes of the curves: points, curve type and radius; no generic attributes
    assert report["attributes"]["radius"] == ["POINT", "FLOAT"]


@pytest.mark.blender
def test_cli_export_of_a_cgh_asset_round_trips_through_blender(tmp_path, capsys):
    import cghair_format
    from cghair_format.cli import main

    asset = example_asset(seed=5, strands=40, points=10)
    cgh, abc, back = tmp_path / "a.cgh", tmp_path / "a.abc", tmp_path / "back.npz"
    cghair_format.write(asset, cgh)
    assert main(["export", str(cgh), "-o", str(abc), "--scale", "100", "--cards"]) == 0
    assert "warning" not in capsys.readouterr().err  # nothing dropped
    assert (tmp_path / "a_cards.png").exists()  # the card atlas the mesh's uv points into
    _, _, geom = groom_props(abc)
    assert {"groom_color", "groom_group_id", "groom_width"} <= set(geom[".arbGeomParams"].props)
    assert main(["convert", str(abc), str(back)]) == 0  # read back through Blender
    src, got = strands_from_asset(cghair_format.read(cgh)), load_strands(back)
    assert list(got.point_counts) == list(src.point_counts)
    expect = src.points * 100 * src.meters_per_unit
    np.testing.assert_allclose(got.points, expect, rtol=0, atol=1e-5 * np.ptp(expect, 0).max())
    np.testing.assert_allclose(got.widths, src.widths * 100 * src.meters_per_unit, rtol=1e-5)


@pytest.mark.blender
@pytest.mark.slow
def test_blender_imports_a_real_groom(tmp_path):
    s = load_strands(hair_path("Ratboy_mohawk.tfx"))
    path = tmp_path / "ratboy.abc"
    export_groom(path, strands=s)
    report, got = blender_import(path, tmp_path)
    assert report["curves"] == s.count and report["points"] == len(s.points)
    assert list(got["sizes"]) == list(s.point_counts)
    k = np.float32(s.meters_per_unit)
    np.testing.assert_array_equal(got["position"] @ got["world"][:3, :3].T,
                                  (s.points * k).astype(np.float64) @ Y_UP_TO_Z_UP.T)


@pytest.mark.blender
def test_blender_imports_the_card_mesh(tmp_path):
    asset = example_asset(seed=7, strands=40, points=10)
    path = tmp_path / "c.abc"
    export_groom(path, asset=asset, cards=True, scale=100)
    report, got = blender_import(path, tmp_path)
    assert report["objects"] == {"Strands": "CURVES", "Cards": "MESH"}
    m = card_mesh(asset.cards)
    assert report["mesh"]["vertices"] == len(m.vertices) and report["mesh"]["polygons"] == len(m.triangles)
    assert report["mesh"]["uv_layers"] == ["uv"]
    k = 100 * asset.meters_per_unit
    world = got["co"] @ got["world"][:3, :3].T + got["world"][:3, 3]
    expect = m.vertices.astype(np.float64) * k @ Y_UP_TO_Z_UP.T
    np.testing.assert_allclose(world, expect, rtol=0, atol=1e-6 * np.abs(expect).max())
    # Blender's face normals (from the winding it reads) agree with the cards' stored normals
    tri = got["corners"].reshape(-1, 3)
    stored = m.normals[tri].mean(1) @ Y_UP_TO_Z_UP.T
    face = got["face_normals"] @ got["world"][:3, :3].T
    assert ((face * stored).sum(1) > 0).mean() > 0.99


@pytest.mark.blender
def test_blender_reads_our_geom_param_encoding(tmp_path):
    """Blender 5.0 imports arbGeomParams of meshes, not of curves: a card mesh carrying groom_color
    encoded exactly as on the curves (per-vertex C3f) shows it with its values, and the mesh's
    ``uv`` (a per-vertex V2f GeomParam, the encoding of groom_root_uv) arrives as its UV map.
    (Blender reads an arbitrary V2f only when indexed, so groom_root_uv itself it skips.)"""
    from cghair_format.exchange.usd_materials import card_atlas

    asset = example_asset(seed=8, strands=20, points=8)
    mesh = card_polymesh(asset, tmp_path / "p.abc")
    n = len(card_mesh(asset.cards).vertices)
    color = np.random.default_rng(1).random((n, 3)).astype(np.float32)
    mesh.properties[0].properties.append(Compound(".arbGeomParams",
                                                  [_geom_param("groom_color", color, "vtx", "rgb")]))
    write_archive(tmp_path / "p.abc", [mesh], {})
    report, got = blender_import(tmp_path / "p.abc", tmp_path)
    assert report["mesh"]["attributes"]["groom_color"] == ["CORNER", "BYTE_COLOR"]
    corners = got["corners"]
    np.testing.assert_allclose(got["attr_groom_color"][:, :3], color[corners], atol=0.5 / 255 + 1e-6)  # 8 bits
    np.testing.assert_allclose(got["attr_uv"], card_atlas(asset)[1][corners], atol=1e-7)
