"""Float fields that make no sense (issue 35): every importer refuses a unit, width, colour, scale, opacity,
rotation or point that is NaN, infinite, beyond float32, or zero or negative where that makes no sense, when
it loads the file, with a StrandFileError naming the file and the field, and without a warning."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cghair_format.exchange import StrandFileError, load_strands, read_3dgs_ply, save_strands
from cghair_format.exchange._ply import write_ply
from cghair_format.strands import Strands

pytestmark = pytest.mark.filterwarnings("error")

NAN, INF = float("nan"), float("inf")
BAD_POSITIVE = (NAN, INF, -INF, 0.0, -1.0)  # units and scales
BAD_NONNEGATIVE = (NAN, INF, -INF, -0.5)  # widths and colours (0 is a fine colour and a fine tip width)


def _strands(**fields) -> Strands:
    """Two strands of 3 points, with colours and widths; ``fields`` replaces whole arrays or sets one entry
    (``widths=(index, value)``)."""
    pts = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0], [1, 0, 0], [1, 1, 0], [1, 2, 0]], np.float32)
    s = Strands(pts, np.array([0, 3, 6]), np.full((6, 3), 0.5, np.float32), np.full(6, 0.01, np.float32))
    for name, value in fields.items():
        array = getattr(s, name).copy()
        index, v = value
        array[index] = v
        setattr(s, name, array)
    return s


def _refused(path: Path, field: str, load: Callable = load_strands) -> str:
    with pytest.raises(StrandFileError) as info:
        load(path)
    message = str(info.value)
    assert str(path) in message and field in message, message
    return message


# --- formats our writers can carry a bad value in ------------------------------------------------------


@pytest.mark.parametrize("ext, field", [(".hair", "thickness"), (".npz", "'widths'")])
@pytest.mark.parametrize("value", BAD_NONNEGATIVE)
def test_bad_widths(tmp_path, ext, field, value):
    path = tmp_path / f"w{ext}"
    save_strands(_strands(widths=(4, value)), path)
    assert "NaN, infinite or negative" in _refused(path, field)


@pytest.mark.parametrize("ext, field", [(".hair", "colours array"), (".npz", "'colors'")])
@pytest.mark.parametrize("value", BAD_NONNEGATIVE)
def test_bad_colours(tmp_path, ext, field, value):
    path = tmp_path / f"c{ext}"
    save_strands(_strands(colors=((2, 1), value)), path)
    _refused(path, field)


@pytest.mark.parametrize("ext, field", [(".hair", "thickness"), (".npz", "'widths'")])
def test_a_strand_of_no_width_is_refused_but_a_tip_of_zero_width_loads(tmp_path, ext, field):
    path = tmp_path / f"z{ext}"
    save_strands(_strands(widths=(slice(3, 6), 0.0)), path)
    assert "1 strands have zero width at every point (the first is strand 1)" in _refused(path, field)
    save_strands(_strands(widths=(2, 0.0)), path)
    assert load_strands(path).widths[2] == 0


@pytest.mark.parametrize("value", BAD_POSITIVE)
def test_npz_units(tmp_path, value):
    path = tmp_path / "u.npz"
    s = _strands()
    np.savez(path, points=s.points, offsets=s.offsets, meters_per_unit=np.float64(value))
    assert "must be a positive finite number" in _refused(path, "'meters_per_unit'")


def test_colours_above_one_are_clipped(tmp_path):
    path = tmp_path / "c.npz"
    save_strands(_strands(colors=((1, 0), 7.5)), path)
    assert load_strands(path).colors[1, 0] == 1.0


def test_tfx_strand_uvs(tmp_path):
    s = _strands()
    s.root_uv = np.array([[0.5, 0.5], [NAN, 0.1]], np.float32)
    path = tmp_path / "uv.tfx"
    save_strands(s, path)
    _refused(path, "strand UVs")


@pytest.mark.parametrize("value", [NAN, INF])
def test_data_points(tmp_path, value):
    """A HairSalon .data holds only points."""
    pts = _strands().points.copy()
    pts[4, 2] = value
    path = tmp_path / "p.data"
    path.write_bytes(struct.pack("<ii", 1, 6) + pts.astype("<f4").tobytes())
    _refused(path, "strand points contain NaN or infinite values")


# --- strand PLY: float colours, a thickness property, double coordinates ----------------------------------


def _strand_ply(path: Path, x: float = 0.0, thickness: float = 0.01, red: float = 0.5) -> Path:
    n = 6
    vertex = {"x": np.array([x, 0, 0, 1, 1, 1], np.float64), "y": np.tile(np.arange(3.0), 2), "z": np.zeros(n),
              "red": np.full(n, red, np.float32), "green": np.full(n, 0.5, np.float32),
              "blue": np.full(n, 0.5, np.float32), "thickness": np.full(n, thickness, np.float32)}
    write_ply(path, [("vertex", vertex), ("strand", {"nsegs": np.array([2, 2], np.uint16)})])
    return path


@pytest.mark.parametrize("value", BAD_NONNEGATIVE)
def test_ply_thickness_and_colours(tmp_path, value):
    _refused(_strand_ply(tmp_path / "t.ply", thickness=value), "'thickness'")
    _refused(_strand_ply(tmp_path / "c.ply", red=value), "vertex colours")


@pytest.mark.parametrize("value", [1e39, -1e300, NAN, INF])
def test_ply_points_beyond_float32(tmp_path, value):
    _refused(_strand_ply(tmp_path / "x.ply", x=value), "vertex x, y, z")


# --- TressFX ASCII: the header's scale and translation, texcoords, point values ---------------------------


def _tfx_ascii(path: Path, scale: str = "1", translation: str = "0 0 0", u: str = "0.5", x: str = "0") -> Path:
    path.write_text(f"version 2.0\nnumStrands 1\nscale {scale}\ntranslation {translation}\nrotation 0 0 0\n"
                    f"strand 0 numVerts 3 texcoord {u} 0.5\n{x} 0 0\n0 1 0\n0 2 0\n")
    return path


@pytest.mark.parametrize("value", BAD_POSITIVE)
def test_tfx_scale(tmp_path, value):
    _refused(_tfx_ascii(tmp_path / "s.tfx", scale=str(value)), "header 'scale'")


def test_tfx_translation_texcoord_and_points(tmp_path):
    _refused(_tfx_ascii(tmp_path / "t.tfx", translation="0 nan 0"), "'translation'")
    _refused(_tfx_ascii(tmp_path / "u.tfx", u="inf"), "texcoord")
    _refused(_tfx_ascii(tmp_path / "x.tfx", x="1e39"), "points (after the header's scale and translation)")
    _refused(_tfx_ascii(tmp_path / "y.tfx", scale="1e30", x="1e10"), "beyond float32")


# --- USD (and Alembic, which Blender turns into USD) ----------------------------------------------------


def _usda(path: Path, mpu: str = "0.01", width: str = "0.01", red: str = "0.5") -> Path:
    path.write_text(f'#usda 1.0\n(\n    metersPerUnit = {mpu}\n)\ndef BasisCurves "hair" {{\n'
                    '  int[] curveVertexCounts = [3]\n  point3f[] points = [(0, 0, 0), (0, 1, 0), (0, 2, 0)]\n'
                    f'  uniform token type = "linear"\n  float[] widths = [0.01, {width}, 0.01] '
                    '(interpolation = "vertex")\n'
                    f'  color3f[] primvars:displayColor = [({red}, 0.5, 0.5)] (interpolation = "constant")\n}}\n')
    return path


@pytest.fixture
def pxr():
    return pytest.importorskip("pxr", reason="usd-core (the usd extra) reads USD")


@pytest.mark.parametrize("value", ["nan", "inf", "0", "-1"])
def test_usd_meters_per_unit(tmp_path, pxr, value):
    _refused(_usda(tmp_path / "m.usda", mpu=value), "metersPerUnit")


@pytest.mark.parametrize("value", ["nan", "inf", "-0.5"])
def test_usd_widths_and_colours(tmp_path, pxr, value):
    _refused(_usda(tmp_path / "w.usda", width=value), "/hair widths")
    _refused(_usda(tmp_path / "c.usda", red=value), "/hair primvars:displayColor")


def test_alembic_names_its_file_not_blenders_stage(tmp_path, pxr, monkeypatch):
    """Alembic reaches strands through Blender's USD export: a bad width it carries is refused naming the
    .abc file (the Blender step is replaced by one that writes the stage Blender would)."""
    from pxr import Usd

    from cghair_format.exchange import alembic

    def fake_worker(op, src, dst):
        Usd.Stage.Open(str(_usda(tmp_path / "blender.usda", width="-1"))).Export(str(dst))

    monkeypatch.setattr(alembic, "run_worker", fake_worker)
    path = tmp_path / "groom.abc"
    path.write_bytes(b"Ogawa")
    message = _refused(path, "/hair widths")
    assert "groom.usdc" not in message


# --- 3DGS PLY ----------------------------------------------------------------------------------------------


def _splat_ply(path: Path, **values: float) -> Path:
    cols = {name: np.zeros(2, np.float64) for name in ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                                        "scale_0", "scale_1", "scale_2", "rot_1", "rot_2",
                                                        "rot_3")}
    cols["rot_0"] = np.ones(2)
    for name, v in values.items():
        cols[name][1] = v
    if "rot_0" in values:
        cols["rot_0"][:] = values["rot_0"]
    write_ply(path, [("vertex", cols)])
    return path


@pytest.mark.parametrize("name, value, words", [
    ("opacity", NAN, "NaN, infinite"), ("opacity", INF, "NaN, infinite"), ("x", 1e39, "beyond float32"),
    ("f_dc_1", NAN, "NaN"), ("scale_2", NAN, "NaN"), ("scale_0", 100.0, "must lie in"),
    ("scale_1", -1000.0, "must lie in"), ("rot_0", 0.0, "zero quaternions"), ("rot_2", -INF, "infinite")])
def test_3dgs_values(tmp_path, name, value, words):
    message = _refused(_splat_ply(tmp_path / "g.ply", **{name: value}), name, read_3dgs_ply)
    assert words in message


def test_3dgs_extreme_opacity_logits_read_without_overflow(tmp_path):
    g = read_3dgs_ply(_splat_ply(tmp_path / "g.ply", opacity=-1000.0))
    assert g.opacities[1] == 0 and g.opacities[0] == 0.5 and math.isclose(float(g.scales[1, 0]), 1.0)


# --- .cgh (the codec's META checks, reached through the strand importer) ---------------------------------


@pytest.mark.parametrize("field, text", [("thickness", "0"), ("thickness", "-1"), ("thickness", "NaN"),
                                         ("meters_per_unit", "0"), ("meters_per_unit", "-0.01"),
                                         ("meters_per_unit", "Infinity")])
def test_cgh_units_and_thickness(tmp_path, field, text):
    from hostile import set_field, small_file

    path = tmp_path / "a.cgh"
    path.write_bytes(set_field(small_file(), (field,), text))
    _refused(path, "META")
