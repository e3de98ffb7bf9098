"""A .cgh asset read as strands: decoded points, band-0 colours, units and up axis."""

from __future__ import annotations

import numpy as np

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
