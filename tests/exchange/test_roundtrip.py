"""Round-trips through every writable format: what a format stores comes back unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cghair_format.exchange import load_strands, save_strands, writable_extensions
from cghair_format.strands import resample

# what each format keeps: colours (and how exactly), widths, units/up axis
KEEPS = {
    ".hair": {"colors": 0.0, "widths": True, "units": False},
    ".data": {"colors": None, "widths": False, "units": False},
    ".tfx": {"colors": None, "widths": False, "units": False},
    ".ply": {"colors": 0.5 / 255, "widths": True, "units": False},
    ".npz": {"colors": 0.0, "widths": True, "units": True},
    ".usd": {"colors": 1e-6, "widths": True, "units": True},  # stored linear, float32
    ".usda": {"colors": 1e-6, "widths": True, "units": True},  # stored linear, float32
    ".usdc": {"colors": 1e-6, "widths": True, "units": True},  # stored linear, float32
    ".usdz": {"colors": 1e-6, "widths": True, "units": True},  # stored linear, float32
}
THROUGH_BLENDER = {".abc"}  # read through Blender: round-tripped in test_alembic.py (metres, y up)


def test_every_writable_format_is_covered():
    assert set(writable_extensions()) == set(KEEPS) | THROUGH_BLENDER


@pytest.mark.parametrize("ext", sorted(KEEPS))
def test_roundtrip(ext, tmp_path, small_strands):
    src = resample(small_strands, 8) if ext == ".tfx" else small_strands  # TressFX: equal counts only
    path = tmp_path / f"s{ext}"
    save_strands(src, path)
    back = load_strands(path)
    keeps = KEEPS[ext]
    np.testing.assert_array_equal(back.offsets, src.offsets)
    np.testing.assert_array_equal(back.points, src.points)
    if keeps["colors"] is None:
        assert back.colors is None
    else:
        np.testing.assert_allclose(back.colors, src.colors, atol=keeps["colors"], rtol=0)
    if keeps["widths"]:
        np.testing.assert_array_equal(back.widths, src.widths)
    if keeps["units"]:
        assert (back.meters_per_unit, back.up_axis) == (src.meters_per_unit, src.up_axis)


def test_tfx_refuses_unequal_point_counts(tmp_path, small_strands):
    from cghair_format.exchange import StrandFileError

    with pytest.raises(StrandFileError, match="resample first"):
        save_strands(small_strands, tmp_path / "x.tfx")


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(counts=st.lists(st.integers(1, 12), min_size=1, max_size=8), seed=st.integers(0, 2**16))
def test_binary_formats_roundtrip_any_strand_lengths(tmp_path, counts, seed):
    from cghair_format.strands import Strands

    rng = np.random.default_rng(seed)
    off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    pts = (rng.normal(size=(off[-1], 3)) * 10 ** rng.uniform(-3, 3)).astype(np.float32)
    s = Strands(pts, off)
    for ext in (".hair", ".data", ".ply", ".npz"):
        path = tmp_path / f"h{ext}"
        save_strands(s, path)
        back = load_strands(path)
        np.testing.assert_array_equal(back.offsets, off)
        np.testing.assert_array_equal(back.points, pts)
