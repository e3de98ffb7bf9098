"""Format-specific behaviour of the strand importers (layouts the real files do not cover)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hairdata import hair_path

from cghair_format.exchange import StrandFileError, load_strands, save_strands
from cghair_format.exchange._ply import write_ply
from cghair_format.strands import Strands


def test_hair_default_segments_and_no_placeholder_attributes(tmp_path):
    # no segments array: every strand has the header's default segment count
    pts = np.arange(2 * 4 * 3, dtype=np.float32)
    header = struct.pack("<4sIIIIff3f88s", b"HAIR", 2, 8, 2, 3, 0.5, 0.0, 0.2, 0.4, 0.6, b"")
    path = tmp_path / "d.hair"
    path.write_bytes(header + pts.tobytes())
    s = load_strands(path)
    assert s.count == 2 and list(s.point_counts) == [4, 4]
    np.testing.assert_array_equal(s.points.ravel(), pts)
    assert s.colors is None and s.widths is None  # header defaults are placeholders, not data


def test_tressfx_ascii_and_binary_agree(tmp_path):
    ascii_strands = load_strands(hair_path("ruby_long_hair_16_guide.tfx"))
    path = tmp_path / "ruby.tfx"
    save_strands(ascii_strands, path)  # written as TressFX 4 binary
    assert path.read_bytes()[:4] == struct.pack("<f", 4.0)
    back = load_strands(path)
    np.testing.assert_array_equal(back.points, ascii_strands.points)


def test_tressfx_binary_versions(tmp_path, small_strands, capsys):
    from cghair_format.strands import resample

    s = resample(small_strands, 4)
    path = tmp_path / "v3.tfx"
    save_strands(s, path)
    capsys.readouterr()
    save_strands(resample(small_strands, 5), tmp_path / "odd.tfx")
    err = capsys.readouterr().err
    assert err.startswith("cgh: warning: ") and "4, 8, 16, 32 or 64" in err and err.count("\n") == 1
    raw = bytearray(path.read_bytes())  # the TressFX 3 layout: tests/exchange/test_hostile_imports.py
    raw[0:4] = struct.pack("<f", 7.0)
    path.write_bytes(bytes(raw))
    with pytest.raises(StrandFileError, match="version field"):
        load_strands(path)


def test_tressfx_ascii_transform_and_truncation(tmp_path):
    text = ("version 2.0\nscale 2.0\nrotation 0 0 0\ntranslation 1 0 0\nnumStrands 2\n"
            "strand 0 numVerts 2 texcoord 0 0\n0 0 0\n0 1 0\nstrand 1 numVerts 3 texcoord 0 0\n1 1 1\n1 2 1\n1 3 1\n")
    path = tmp_path / "a.tfx"
    path.write_text(text)
    s = load_strands(path)
    assert list(s.point_counts) == [2, 3]
    np.testing.assert_allclose(s.points[1], [1, 2, 0])  # 2 * (0, 1, 0) + (1, 0, 0)
    path.write_text(text.rsplit("\n", 3)[0] + "\n")
    with pytest.raises(StrandFileError, match="a.tfx"):
        load_strands(path)


def _vertex_cols(points: np.ndarray) -> dict:
    return {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}


def test_ply_vertex_only_fixed_count(tmp_path):
    pts = np.random.default_rng(0).normal(size=(5 * 100, 3)).astype(np.float32)
    path = tmp_path / "gh.ply"
    zeros = np.zeros(len(pts), np.float32)  # GaussianHaircut's layout: x y z nx ny nz, 100 points a strand
    write_ply(path, [("vertex", _vertex_cols(pts) | {"nx": zeros, "ny": zeros, "nz": zeros})])
    s = load_strands(path)  # GaussianHaircut's 100 points per strand
    assert s.count == 5 and set(s.point_counts) == {100}
    s = load_strands(path, points_per_strand=50)
    assert s.count == 10
    write_ply(path, [("vertex", _vertex_cols(pts))], comments=["points_per_strand 25"])
    assert load_strands(path).count == 20
    write_ply(path, [("vertex", _vertex_cols(pts[:499]))])
    with pytest.raises(StrandFileError, match="--points-per-strand"):
        load_strands(path)


def test_ply_edge_only_and_strand_id_layouts(tmp_path):
    pts = np.random.default_rng(1).normal(size=(9, 3)).astype(np.float32)
    v1 = np.array([0, 1, 3, 4, 5, 7], np.int32)  # strands [0..2], [3..6], [7..8]
    path = tmp_path / "edges.ply"
    write_ply(path, [("vertex", _vertex_cols(pts)), ("edge", {"vertex1": v1, "vertex2": v1 + 1})])
    assert list(load_strands(path).point_counts) == [3, 4, 2]
    cols = _vertex_cols(pts) | {"strand_id": np.array([0, 0, 1, 1, 1, 1, 2, 2, 2], np.int32)}
    write_ply(path, [("vertex", cols)])
    assert list(load_strands(path).point_counts) == [2, 4, 3]


def test_ply_ascii_and_big_endian(tmp_path, small_strands):
    s = small_strands
    lines = ["ply", "format ascii 1.0", f"element vertex {len(s.points)}", "property float x",
             "property float y", "property float z", f"element strand {s.count}", "property int nsegs",
             "end_header"]
    lines += [" ".join(repr(float(v)) for v in p) for p in s.points]
    lines += [str(c - 1) for c in s.point_counts]
    path = tmp_path / "a.ply"
    path.write_text("\n".join(lines) + "\n")
    np.testing.assert_array_equal(load_strands(path).points, s.points)
    head = "\n".join(["ply", "format binary_big_endian 1.0", *lines[2:9]]) + "\n"
    body = s.points.astype(">f4").tobytes() + (s.point_counts - 1).astype(">i4").tobytes()
    path.write_bytes(head.encode() + body)
    back = load_strands(path)
    np.testing.assert_array_equal(back.points, s.points)
    np.testing.assert_array_equal(back.offsets, s.offsets)


def test_npz_equal_length_array(tmp_path):
    arr = np.random.default_rng(2).normal(size=(4, 6, 3)).astype(np.float32)
    path = tmp_path / "a.npz"
    np.savez(path, strands=arr)
    np.testing.assert_array_equal(load_strands(path).to_array(), arr)
    np.savez(path, something=arr)
    with pytest.raises(StrandFileError, match="expected arrays"):
        load_strands(path)


def test_strands_validate_catches_bad_offsets():
    with pytest.raises(Exception, match="offsets"):
        Strands(np.zeros((3, 3), np.float32), np.array([0, 2], np.int64)).validate()


def test_strand_ply_opens_in_an_independent_reader(tmp_path, small_strands):
    """trimesh reads our hapPLY-layout file as a 3D path with one entity per strand."""
    trimesh = pytest.importorskip("trimesh")
    path = tmp_path / "s.ply"
    save_strands(small_strands, path)
    loaded = trimesh.load(path, process=False)
    np.testing.assert_array_equal(np.asarray(loaded.vertices, np.float32), small_strands.points)
    raw = loaded.metadata["_ply_raw"]
    np.testing.assert_array_equal(raw["strand"]["data"]["nsegs"], small_strands.point_counts - 1)
    assert len(raw["edge"]["data"]) == len(small_strands.points) - small_strands.count


def test_tressfx_keeps_root_uvs(tmp_path):
    """Ratboy_mohawk.tfx stores real strand UVs: they load, and write back instead of zeros."""
    from hairdata import hair_path

    s = load_strands(hair_path("Ratboy_mohawk.tfx"))
    assert s.root_uv is not None and s.root_uv.shape == (s.count, 2)
    assert 0 < s.root_uv.min() and s.root_uv.max() < 1 and len(np.unique(s.root_uv, axis=0)) > s.count // 2
    path = tmp_path / "r.tfx"
    save_strands(s, path)
    np.testing.assert_array_equal(load_strands(path).root_uv, s.root_uv)
    text = ("version 2.0\nnumStrands 2\nstrand 0 numVerts 2 texcoord 0.25 0.5\n0 0 0\n0 1 0\n"
            "strand 1 numVerts 2 texcoord 0.75 0.125\n1 1 1\n1 2 1\n")
    (tmp_path / "a.tfx").write_text(text)
    np.testing.assert_array_equal(load_strands(tmp_path / "a.tfx").root_uv, [[0.25, 0.5], [0.75, 0.125]])
