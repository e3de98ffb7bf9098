"""A real DCC opens our USD: Blender (bpy 5.0 as a Python module) imports the exported stage.

bpy pins numpy < 2, so it lives in its own virtual environment (``make blender`` puts it in
``.venv/blender``; ``CGH_BLENDER_PYTHON`` names another interpreter). Blender runs in a
subprocess so a crash cannot take pytest down. When no interpreter with bpy exists the test
FAILS (CI installs bpy; deselect locally with ``-m "not blender"``).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cghair_format.examples import example_asset
from cghair_format.exchange._common import srgb_to_linear
from cghair_format.exchange.blender import BlenderNotFoundError, find_blender_python
from cghair_format.exchange.cgh_strands import strand_colors
from cghair_format.exchange.usd_export import export_usd
from cghair_format.gaussians import decode_points
from cghair_format.geometry import card_mesh
from cghair_format.synth import synthesize

RTOL = 1e-5  # positions must agree to 1e-5 of the model's bounding-box diagonal

BLENDER_SCRIPT = r"""
import json, sys
import bpy
import numpy as np

jobs = json.loads(sys.argv[-1])
report = {}
for usd_path, out_npz in jobs:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.wm.usd_import(filepath=usd_path)
    objs = {o.name: o.type for o in bpy.data.objects}
    curves = [o for o in bpy.data.objects if o.type == "CURVES"]
    entry = {"result": sorted(result), "objects": objs, "curves_objects": len(curves)}
    if curves:
        o = curves[0]
        d = o.data
        pos = np.empty(len(d.points) * 3, np.float32)
        d.attributes["position"].data.foreach_get("vector", pos)
        arrays = {"position": pos.reshape(-1, 3), "world": np.array(o.matrix_world, np.float64),
                  "sizes": np.array([c.points_length for c in d.curves], np.int64)}
        attrs = {a.name: [a.domain, a.data_type] for a in d.attributes}
        if "displayColor" in d.attributes:
            col = np.empty(len(d.points) * 4, np.float32)
            d.attributes["displayColor"].data.foreach_get("color", col)
            arrays["displayColor"] = col.reshape(-1, 4)[:, :3]
        if "radius" in d.attributes:
            rad = np.empty(len(d.points), np.float32)
            d.attributes["radius"].data.foreach_get("value", rad)
            arrays["radius"] = rad
        np.savez(out_npz, **arrays)
        entry.update(curves=len(d.curves), points=len(d.points), attributes=attrs)
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    entry["meshes"] = {o.name: {"vertices": len(o.data.vertices), "polygons": len(o.data.polygons),
                                "uv_layers": [uv.name for uv in o.data.uv_layers]} for o in meshes}
    report[usd_path] = entry
print("CGH_REPORT " + json.dumps(report))
"""


def blender_python() -> str:
    try:
        return find_blender_python()
    except BlenderNotFoundError as exc:
        pytest.fail(f"{exc}. Deselect this test with -m 'not blender'.")


def run_blender(jobs: list[tuple[Path, Path]]) -> dict:
    proc = subprocess.run([blender_python(), "-c", BLENDER_SCRIPT, json.dumps([[str(a), str(b)] for a, b in jobs])],
                          capture_output=True, text=True, timeout=300)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("CGH_REPORT ")]
    assert proc.returncode == 0 and lines, f"Blender failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    return json.loads(lines[-1][len("CGH_REPORT "):])


Y_UP_TO_Z_UP = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)  # Blender's import rotation


@pytest.mark.blender
def test_blender_imports_exported_usd(tmp_path):
    asset = example_asset(seed=11, strands=48, points=12, sh_degree=1)
    asset_usd = tmp_path / "asset.usda"
    export_usd(asset_usd, asset=asset, curves=True, cards=True, gaussians=True)
    strands = synthesize("curly", 200, 24, seed=4)
    strands_usd = tmp_path / "strands.usdc"
    export_usd(strands_usd, strands=strands)
    jobs = [(asset_usd, tmp_path / "asset.npz"), (strands_usd, tmp_path / "strands.npz")]
    report = run_blender(jobs)

    cases = [(asset_usd, decode_points(asset).reshape(-1, 3), strand_colors(asset).reshape(-1, 3),
              [asset.points_per_strand] * asset.n_strands),
             (strands_usd, strands.points, strands.colors, list(strands.point_counts))]
    for (usd, npz), (_, points, colors, sizes) in zip(jobs, cases, strict=True):
        entry = report[str(usd)]
        assert entry["result"] == ["FINISHED"], entry
        assert entry["curves_objects"] == 1, entry["objects"]
        assert entry["curves"] == len(sizes) and entry["points"] == len(points)
        got = np.load(npz)
        assert list(got["sizes"]) == sizes
        scale = float(np.linalg.norm(points.max(0) - points.min(0)))
        np.testing.assert_allclose(got["position"], points, rtol=0, atol=RTOL * scale)
        # Blender turns our y-up stage into its z-up world with the object transform
        world = got["position"] @ got["world"][:3, :3].T + got["world"][:3, 3]
        np.testing.assert_allclose(world, points @ Y_UP_TO_Z_UP.T, rtol=0, atol=RTOL * scale)
        assert entry["attributes"]["displayColor"] == ["POINT", "FLOAT_COLOR"]
        np.testing.assert_allclose(got["displayColor"], srgb_to_linear(colors), atol=1e-6)  # USD colours are linear
    # USD widths are diameters, Blender radii are half of them
    np.testing.assert_allclose(np.load(jobs[0][1])["radius"], asset.thickness, rtol=1e-6)
    # the cards arrive as a mesh with their UVs
    cards = card_mesh(asset.cards)
    assert report[str(asset_usd)]["meshes"]["Cards"] == {
        "vertices": len(cards.vertices), "polygons": len(cards.triangles), "uv_layers": ["st"]}


BLENDER_REEXPORT = r"""
import json, sys
import bpy
import numpy as np

for src, dst, kind in json.loads(sys.argv[-1]):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=src)
    obj = [o for o in bpy.data.objects if o.type == "CURVES"][0]
    d = obj.data
    if kind != "POLY":
        d.set_types(type=kind)
    if kind == "BEZIER":  # set_types leaves the handles unset: give them Catmull-Rom tangents
        p = np.empty(len(d.points) * 3, np.float32)
        d.attributes["position"].data.foreach_get("vector", p)
        p = p.reshape(-1, 3)
        sizes = [c.points_length for c in d.curves]
        left, right, start = p.copy(), p.copy(), 0
        for n in sizes:
            q = p[start:start + n]
            tangent = np.gradient(q, axis=0) / 3
            left[start:start + n] = q - tangent
            right[start:start + n] = q + tangent
            start += n
        for name, value in (("handle_left", left), ("handle_right", right)):
            if name not in d.attributes:
                d.attributes.new(name, "FLOAT_VECTOR", "POINT")
            d.attributes[name].data.foreach_set("vector", value.ravel())
    assert bpy.ops.wm.usd_export(filepath=dst) == {"FINISHED"}
print("CGH_REPORT {}")
"""


@pytest.mark.blender
@pytest.mark.parametrize("kind,step", [("POLY", 1), ("CATMULL_ROM", None), ("BEZIER", None)])
def test_curves_blender_writes_load_back(tmp_path, kind, step):
    """Blender re-exports our curves (as linear, Catmull-Rom pinned or Bezier cubics, with vertex or
    varying primvars, under a z-up transform): load_strands must recover the same strands."""
    from cghair_format.exchange import load_strands
    from cghair_format.exchange.usd_curves import CUBIC_SAMPLES

    strands = synthesize("wavy", 30, 9, seed=2)
    src, dst = tmp_path / "ours.usda", tmp_path / f"blender_{kind}.usda"
    export_usd(src, strands=strands)
    proc = subprocess.run([blender_python(), "-c", BLENDER_REEXPORT, json.dumps([[str(src), str(dst), kind]])],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and dst.exists(), f"Blender failed:\n{proc.stderr[-3000:]}"
    back = load_strands(dst)
    step = step or CUBIC_SAMPLES  # the original points sit at the cubic segment ends
    assert back.up_axis == "Z" and back.count == strands.count
    n = strands.point_counts[0]
    assert set(back.point_counts) == {(n - 1) * step + 1}
    at_points = (back.offsets[:-1, None] + np.arange(n)[None, :] * step).ravel()
    scale = strands.bbox_diagonal()
    np.testing.assert_allclose(back.points[at_points], strands.points @ Y_UP_TO_Z_UP.T, rtol=0, atol=RTOL * scale)
    np.testing.assert_allclose(back.colors[at_points], strands.colors, atol=1e-6)
    np.testing.assert_allclose(back.widths[at_points], strands.widths, rtol=1e-6)


def test_missing_blender_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("CGH_BLENDER_PYTHON", str(tmp_path / "no-python"))
    with pytest.raises(BlenderNotFoundError, match="does not exist"):
        find_blender_python()


@pytest.mark.blender
def test_alembic_round_trip_through_cli(tmp_path, capsys):
    """`cgh export X.cgh -o X.abc` (our writer) and `cgh convert X.abc Y` (through Blender): the
    strands come back in metres, y up, scaled by --scale, with their widths."""
    import cghair_format
    from cghair_format.cli import main
    from cghair_format.exchange import load_strands
    from cghair_format.exchange.cgh_strands import strands_from_asset

    asset = example_asset(seed=5, strands=40, points=10)
    cgh = tmp_path / "a.cgh"
    cghair_format.write(asset, cgh)
    abc, back = tmp_path / "a.abc", tmp_path / "back.npz"
    assert main(["export", str(cgh), "-o", str(abc), "--scale", "100"]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main(["convert", str(abc), str(back)]) == 0
    src, got = strands_from_asset(cghair_format.read(cgh)), load_strands(back)
    assert got.count == src.count and list(got.point_counts) == list(src.point_counts)
    assert got.up_axis == "Y" and src.up_axis == "Y"
    expect = src.points * 100 * src.meters_per_unit  # Blender keeps metres
    np.testing.assert_allclose(got.points, expect, rtol=0, atol=RTOL * np.ptp(expect, 0).max())
    np.testing.assert_allclose(got.widths, src.widths * 100 * src.meters_per_unit, rtol=1e-5)
