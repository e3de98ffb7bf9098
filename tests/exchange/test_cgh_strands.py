"""A .cgh asset read as strands: decoded points, band-0 colours, units and up axis."""

from __future__ import annotations

import numpy as np
import pytest

import cghair_format
from cghair_format.examples import example_asset
from cghair_format.exchange import load_strands, save_strands
from cghair_format.gaussians import decode_points


def test_cgh_file_as_strands(tmp_path):
    asset = example_asset(seed=5)
    asset.meters_per_unit = 0.01
    path = tmp_path / "a.cgh"
    cghair_format.write(asset, path, profile="lossless")
    s = load_strands(path)
    np.testing.assert_allclose(s.to_array(), decode_points(cghair_format.read(path)), atol=0)
    assert s.meters_per_unit == 0.01 and s.up_axis == asset.up_axis
    assert s.colors.shape == (len(s.points), 3) and 0 <= s.colors.min() and s.colors.max() <= 1
    out = tmp_path / "a.ply"
    save_strands(s, out)
    assert load_strands(out).count == asset.n_strands


def test_a_variable_count_asset_exports_each_strand_with_its_own_points(tmp_path):
    from cghair_format.examples import with_point_counts
    from cghair_format.exchange import StrandFileError, export_usd
    from cghair_format.geometry import strand_points

    asset = with_point_counts(example_asset(seed=5, strands=24, points=12), seed=3)
    path = tmp_path / "v.cgh"
    cghair_format.write(asset, path, profile="lossless")
    s = load_strands(path)
    assert np.array_equal(s.point_counts, asset.counts)
    padded = strand_points(asset.cards, asset.strand_card, asset.uvd)
    np.testing.assert_array_equal(s.points, padded[asset.real_points()])
    assert len(s.colors) == len(s.widths) == len(s.points)
    for ext in (".npz", ".hair", ".ply", ".usda"):
        save_strands(s, tmp_path / f"v{ext}")
        back = load_strands(tmp_path / f"v{ext}")
        assert np.array_equal(back.point_counts, asset.counts), ext
        np.testing.assert_allclose(back.points, s.points, rtol=0, atol=1e-6)
    export_usd(tmp_path / "asset.usda", asset=cghair_format.read(path))
    assert np.array_equal(load_strands(tmp_path / "asset.usda").point_counts, asset.counts)
    with pytest.raises(StrandFileError, match="--points"):
        save_strands(s, tmp_path / "v.tfx")
