"""Vertex-only strand PLYs whose strands are told apart by a change of per-strand colour."""

from __future__ import annotations

import numpy as np
import pytest
from hairdata import hair_path

from cghair_format.exchange import StrandFileError, load_strands
from cghair_format.exchange._ply import read_ply, write_ply


def _vertex_only(path, points, colours, comments=()):
    cols = {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
    if colours.dtype == np.uint8:
        cols |= {"red": colours[:, 0], "green": colours[:, 1], "blue": colours[:, 2]}
    else:
        cols |= {"r": colours[:, 0], "g": colours[:, 1], "b": colours[:, 2]}
    write_ply(path, [("vertex", cols)], comments=list(comments))
    return path


def _per_strand(counts, palette):
    return np.repeat(np.asarray(palette), counts, axis=0)


def test_colour_boundaries_split_strands(tmp_path):
    counts = [30, 70, 60, 40]  # 200 vertices: a fixed 100 would make 2 strands
    pts = np.random.default_rng(0).normal(size=(200, 3)).astype(np.float32)
    palette = np.array([[200, 10, 10], [10, 200, 10], [10, 10, 200], [200, 10, 10]], np.uint8)
    path = _vertex_only(tmp_path / "c.ply", pts, _per_strand(counts, palette))
    s = load_strands(path)
    assert list(s.point_counts) == counts
    np.testing.assert_array_equal(s.points, pts)
    # float colours (r, g, b) delimit the same way
    path = _vertex_only(tmp_path / "f.ply", pts, _per_strand(counts, palette / 255.0).astype(np.float32))
    assert list(load_strands(path).point_counts) == counts


def test_a_stated_count_must_agree_with_the_colours(tmp_path):
    counts = [30, 70, 60, 40]
    pts = np.zeros((200, 3), np.float32)
    colours = _per_strand(counts, np.arange(12, dtype=np.uint8).reshape(4, 3))
    path = _vertex_only(tmp_path / "c.ply", pts, colours, ["points_per_strand 50"])
    with pytest.raises(StrandFileError, match="4 strands of 30..70 points, which disagrees with 50 points per strand"):
        load_strands(path)
    with pytest.raises(StrandFileError, match="disagrees with 20 points"):
        load_strands(_vertex_only(tmp_path / "d.ply", pts, colours), points_per_strand=20)
    assert list(load_strands(path, points_per_strand=10).point_counts) == [10] * 20  # every change on a multiple


def test_fixed_count_separates_neighbours_of_one_colour(tmp_path):
    # GaussianHaircut-style 100-point strands; strands 1 and 2 share a colour: colours alone would merge them
    pts = np.zeros((400, 3), np.float32)
    colours = _per_strand([100] * 4, np.array([[1, 1, 1], [2, 2, 2], [2, 2, 2], [3, 3, 3]], np.uint8))
    assert list(load_strands(_vertex_only(tmp_path / "g.ply", pts, colours)).point_counts) == [100] * 4


def test_per_vertex_colours_do_not_split(tmp_path):
    pts = np.zeros((300, 3), np.float32)
    ramp = np.tile(np.linspace(0, 255, 100).astype(np.uint8)[:, None].repeat(3, 1), (3, 1))  # root-to-tip ramp
    assert list(load_strands(_vertex_only(tmp_path / "r.ply", pts, ramp)).point_counts) == [100] * 3
    with pytest.raises(StrandFileError, match="cannot split 299 vertices"):
        load_strands(_vertex_only(tmp_path / "s.ply", pts[:299], ramp[:299]))


@pytest.mark.parametrize("name", ["Curly_100.ply", "Bangs_100_binary.ply"])
def test_real_files_without_their_strand_element(tmp_path, name):
    """CT2Hair's files colour each strand: with only their vertices left, the colours find the strands."""
    original = load_strands(hair_path(name))
    v = read_ply(hair_path(name)).elements["vertex"].data
    pts = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float32)
    colours = np.stack([v["red"], v["green"], v["blue"]], 1)
    back = load_strands(_vertex_only(tmp_path / name, pts, colours))
    np.testing.assert_array_equal(back.offsets, original.offsets)
    np.testing.assert_array_equal(back.points, original.points)
    assert back.count == 100 and len(set(back.point_counts)) > 5  # variable lengths, as in the file
