"""Every real file in ../shared/data/hair loads with the counts PROVENANCE.md gives."""

from __future__ import annotations

import numpy as np
import pytest
from hairdata import REAL_FILES, hair_path

from cghair_format.exchange import load_strands


@pytest.mark.parametrize("name", sorted(REAL_FILES))
def test_real_file_counts(name):
    strands = load_strands(hair_path(name))
    n, lo, hi, total = REAL_FILES[name]
    counts = strands.point_counts
    assert strands.count == n
    assert (counts.min(), counts.max()) == (lo, hi)
    assert len(strands.points) == total
    assert np.isfinite(strands.points).all()
    assert strands.bbox_diagonal() > 0
    # consecutive points of a strand are close compared with the model's size (no mis-split strands)
    seg = np.linalg.norm(np.diff(strands.points, axis=0), axis=1)
    inner = np.ones(len(seg), bool)
    inner[strands.offsets[1:-1] - 1] = False
    assert np.median(seg[inner]) < 0.1 * strands.bbox_diagonal()


def test_four_bangs_files_give_the_same_strands():
    loaded = [load_strands(hair_path(f"Bangs_100{suffix}"))
              for suffix in (".hair", ".data", "_binary.ply", "_ascii.ply")]
    ref = loaded[0]
    for other in loaded[1:]:
        assert np.array_equal(other.offsets, ref.offsets)
        # the ASCII PLY prints 6 significant digits
        np.testing.assert_allclose(other.points, ref.points, rtol=1e-5, atol=1e-4)
    # the PLY files carry one colour per strand (each file its own random palette)
    for ply in loaded[2:]:
        first = np.repeat(ply.colors[ply.offsets[:-1]], ply.point_counts, axis=0)
        np.testing.assert_array_equal(ply.colors, first)


def test_tressfx_files_are_y_up_and_colour_files_have_colours():
    assert load_strands(hair_path("Ratboy_mohawk.tfx")).up_axis == "Y"
    straight = load_strands(hair_path("straight.hair"))
    assert straight.colors is not None and straight.colors.shape == (160_000, 3)
    assert 0 <= straight.colors.min() and straight.colors.max() <= 1


def test_units_and_up_overrides():
    s = load_strands(hair_path("straight.hair"), units=0.01, up="z")
    assert (s.meters_per_unit, s.up_axis) == (0.01, "Z")
