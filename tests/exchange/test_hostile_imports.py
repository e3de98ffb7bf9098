"""Crafted and mutated strand files (issue 21): every importer refuses them with a StrandFileError naming
the file, checks sizes before it allocates (peak traced memory), and takes under a second."""

from __future__ import annotations

import io
import struct
import time
import tracemalloc
import zipfile

import numpy as np
import pytest

from cghair_format.errors import CghError
from cghair_format.exchange import StrandFileError, load_strands, save_strands
from cghair_format.exchange.hair import HEADER as HAIR_HEADER

MAX_SECONDS = 1.0
MAX_TRACED = 64 << 20


def _refused(path, match: str | None = None) -> StrandFileError:
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(StrandFileError, match=match) as info:
            load_strands(path)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - start < MAX_SECONDS
    assert peak < MAX_TRACED, peak
    assert str(path) in str(info.value)
    return info.value


def test_hair_header_cannot_allocate_beyond_the_file(tmp_path):
    """128 bytes declaring 2^30 strands of 2^32 - 1 points, without a segments array (the default
    segment count then applies to every strand): refused before the per-strand array is made."""
    path = tmp_path / "big.hair"
    path.write_bytes(HAIR_HEADER.pack(b"HAIR", 1 << 30, (1 << 32) - 1, 2, 3, 1.0, 1.0, 1, 1, 1, b""))
    _refused(path, "cannot hold")


def _hair(tmp_path, small_strands, name, edit):
    path = tmp_path / name
    edit(small_strands)
    save_strands(small_strands, path)
    return path


def test_nan_widths_and_colours_are_refused(tmp_path, small_strands):
    def nan_width(s):
        s.widths[3] = np.nan

    def nan_colour(s):
        s.colors = s.colors.copy()
        s.colors[4, 1] = np.nan

    _refused(_hair(tmp_path, small_strands, "w.hair", nan_width), "widths contain NaN")
    path = tmp_path / "c.hair"
    save_strands(small_strands, path)  # the writer clips nothing: poke the NaN into the colours array
    raw = bytearray(path.read_bytes())
    raw[-12 * 5 + 4:-12 * 5 + 8] = struct.pack("<f", np.nan)
    path.write_bytes(bytes(raw))
    _refused(path, "colors contain NaN")
    nan_colour(small_strands)
    path = tmp_path / "c.npz"
    save_strands(small_strands, path)
    _refused(path, "colors contain NaN")


def test_zero_point_strands_are_refused(tmp_path):
    path = tmp_path / "z.npz"
    np.savez(path, points=np.zeros((4, 3), np.float32), offsets=np.array([0, 2, 2, 4]))
    _refused(path, "1 strands have no points")


def test_usda_that_is_not_utf8(tmp_path):
    pytest.importorskip("pxr", reason="usd-core (the usd extra) reads USD")
    from pxr import Usd  # noqa: F401  (imported before the clock starts: its first import takes seconds)

    path = tmp_path / "latin1.usda"
    path.write_bytes(b'#usda 1.0\n(\n    doc = "caf\xe9"\n)\ndef BasisCurves "hair" {\n'
                     b'  int[] curveVertexCounts = [2]\n  point3f[] points = [(0,0,0),(1,1,1)]\n'
                     b'  uniform token type = "linear"\n}\n')
    _refused(path, "UTF-8")


def _npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def test_npz_whose_header_declares_a_huge_array(tmp_path):
    """An .npy header in the archive that declares 10^12 x 3 floats: refused before numpy allocates."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        head = io.BytesIO()
        np.lib.format.write_array_header_1_0(head, {"descr": "<f4", "fortran_order": False,
                                                    "shape": (10 ** 12, 3)})
        z.writestr("points.npy", head.getvalue() + bytes(64))
        z.writestr("offsets.npy", _npy(np.array([0, 1], np.int64)))
    path = tmp_path / "huge.npz"
    path.write_bytes(buf.getvalue())
    _refused(path, "declares")


def _npy(a: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, a)
    return out.getvalue()


@pytest.mark.parametrize("arrays, match", [
    ({"points": np.array([["a", "b", "c"]]), "offsets": np.array([0, 1])}, "not a real number type"),
    ({"points": np.zeros((2, 3), np.float32), "offsets": np.array([0, 2]), "meters_per_unit": np.ones(3)},
     "wrong type"),
    ({"points": np.zeros((2, 3), np.float32), "offsets": np.array([0, 2]), "widths": np.ones((2, 2))}, "shape"),
    ({"points": np.zeros((2, 3), np.complex64), "offsets": np.array([0, 2])}, "not a real number type"),
])
def test_npz_with_arrays_of_the_wrong_kind(tmp_path, arrays, match):
    path = tmp_path / "bad.npz"
    path.write_bytes(_npz_bytes(**arrays))
    _refused(path, match)


def test_npz_with_a_corrupt_deflate_stream(tmp_path):
    data = bytearray(_npz_bytes(points=np.arange(3000, dtype=np.float32).reshape(-1, 3),
                                offsets=np.array([0, 1000])))
    start = data.index(b"points.npy") + len("points.npy")  # the member's compressed bytes follow its name
    for i in range(start + 8, start + 40):
        data[i] ^= 0x5A
    path = tmp_path / "zlib.npz"
    path.write_bytes(bytes(data))
    _refused(path)


def test_ply_comment_that_is_not_a_number(tmp_path):
    path = tmp_path / "c.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\ncomment points_per_strand abc\nelement vertex 2\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n")
    _refused(path, "points_per_strand abc")


EXTENSIONS = (".hair", ".data", ".tfx", ".ply", ".npz", ".usda")


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_mutated_files_raise_only_strand_file_errors(tmp_path, small_strands, ext):
    """300 seeded mutations (byte changes, cuts, insertions) of a valid file: each loads or is refused
    with a CghError naming the file, in under a second."""
    if ext == ".usda":
        pytest.importorskip("pxr", reason="usd-core (the usd extra) reads USD")
    if ext == ".tfx":
        from cghair_format.strands import resample

        small_strands = resample(small_strands, 8)
    path = tmp_path / f"base{ext}"
    save_strands(small_strands, path)
    base = path.read_bytes()
    rng = np.random.default_rng(21)
    for i in range(300):
        data = bytearray(base)
        pos = int(rng.integers(0, len(data)))
        kind = i % 3
        if kind == 0:
            for p in rng.integers(0, len(data), int(rng.integers(1, 5))):
                data[p] = int(rng.integers(0, 256))
        elif kind == 1:
            del data[pos:]
        else:
            data[pos:pos] = rng.integers(0, 256, int(rng.integers(1, 9)), dtype=np.uint8).tobytes()
        bad = tmp_path / f"m{i}{ext}"
        bad.write_bytes(bytes(data))
        start = time.perf_counter()
        try:
            load_strands(bad)
        except CghError as exc:
            assert str(bad) in str(exc), exc
        assert time.perf_counter() - start < MAX_SECONDS
        bad.unlink()


def _tfx3(points: np.ndarray, version: float = 3.0, positions_at: int = 304) -> bytes:
    """A TressFX 3 binary (TressFXFileObject: 296-byte header, positions offset at byte 144, float3)."""
    s, p = points.shape[:2]
    head = bytearray(296)
    struct.pack_into("<fIII", head, 0, version, s, p, 0)
    struct.pack_into("<I", head, 144, positions_at)
    return bytes(head) + bytes(max(positions_at - 296, 0)) + points.astype("<f4").tobytes()


def test_tressfx3_binary(tmp_path):
    rng = np.random.default_rng(3)
    points = np.cumsum(rng.normal(size=(5, 8, 3)), axis=1).astype(np.float32)
    path = tmp_path / "v3.tfx"
    path.write_bytes(_tfx3(points))
    strands = load_strands(path)
    assert strands.count == 5 and strands.up_axis == "Y"
    np.testing.assert_array_equal(strands.points, points.reshape(-1, 3))
    path.write_bytes(_tfx3(points)[:-4])
    _refused(path, "truncated")
    path.write_bytes(_tfx3(points, positions_at=200))
    _refused(path, "inside the 296-byte header")
