"""Strand operations: resampling (arc length, B-spline) and densification."""

from __future__ import annotations

import numpy as np
import pytest

from cghair_format.errors import AssetError
from cghair_format.strands import Strands, bbox_diagonal, densify, resample


def _helix(n_strands=6, n_points=40, seed=0) -> Strands:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 4 * np.pi, n_points)
    roots = rng.normal(size=(n_strands, 1, 3))
    pts = roots + np.stack([np.cos(t), np.sin(t), 0.3 * t], -1)[None]
    return Strands.from_array(pts.astype(np.float32))


def _varying(seed=1) -> Strands:
    rng = np.random.default_rng(seed)
    counts = rng.integers(3, 30, 12)
    off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    pts = np.cumsum(rng.uniform(0.1, 1.0, (off[-1], 3)), 0).astype(np.float32)
    colors = rng.random((off[-1], 3)).astype(np.float32)
    return Strands(pts, off, colors, rng.uniform(0.1, 0.2, off[-1]).astype(np.float32), 0.01, "Z")


@pytest.mark.parametrize("method", ["arclength", "bspline"])
def test_resample_counts_ends_and_metadata(method):
    s = _varying()
    r = resample(s, 17, method)
    assert r.count == s.count and set(r.point_counts) == {17}
    a = r.to_array()
    np.testing.assert_allclose(a[:, 0], s.points[s.offsets[:-1]], atol=1e-5)
    np.testing.assert_allclose(a[:, -1], s.points[s.offsets[1:] - 1], atol=1e-5)
    assert (r.meters_per_unit, r.up_axis) == (0.01, "Z")
    assert r.colors.shape == (len(r.points), 3) and r.widths.shape == (len(r.points),)
    assert 0 <= r.colors.min() and r.colors.max() <= 1


def test_arclength_points_lie_on_the_polyline_equally_spaced():
    s = Strands.from_array(np.array([[[0, 0, 0], [1, 0, 0], [1, 3, 0]]], np.float32))  # L-shape, length 4
    r = resample(s, 5)
    np.testing.assert_allclose(r.points, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 2, 0], [1, 3, 0]], atol=1e-6)


def test_bspline_follows_a_smooth_curve_better_than_its_polyline():
    fine = _helix(n_points=400)
    coarse = resample(fine, 20)
    truth = resample(fine, 64).to_array()
    err = {m: np.abs(resample(coarse, 64, m).to_array() - truth).max() for m in ("arclength", "bspline")}
    assert err["bspline"] < 0.5 * err["arclength"], err


def test_resample_handles_degenerate_strands():
    s = Strands(np.array([[1, 2, 3], [0, 0, 0], [0, 0, 0], [5, 5, 5], [6, 5, 5]], np.float32),
                np.array([0, 1, 3, 5], np.int64))  # 1 point, zero-length, normal
    r = resample(s, 4)
    a = r.to_array()
    np.testing.assert_array_equal(a[0], np.repeat([[1, 2, 3]], 4, 0))
    np.testing.assert_array_equal(a[1], 0)
    np.testing.assert_allclose(a[2, :, 0], [5, 5 + 1 / 3, 5 + 2 / 3, 6], atol=1e-6)
    with pytest.raises(AssetError, match="at least 2"):
        resample(s, 1)
    with pytest.raises(AssetError, match="method"):
        resample(s, 4, "cubic")


def test_densify_adds_strands_between_neighbours():
    s = _varying()
    d = densify(s, 100, seed=3, n_points=10)
    assert d.count == 100 and set(d.point_counts) == {10}
    a = d.to_array()
    base = resample(s, 10).to_array()
    np.testing.assert_array_equal(a[:s.count], base)  # originals kept first
    # new roots lie inside the bounding box of the original roots (convex blends)
    lo, hi = base[:, 0].min(0), base[:, 0].max(0)
    assert ((a[s.count:, 0] >= lo - 1e-5) & (a[s.count:, 0] <= hi + 1e-5)).all()
    # new strand lengths stay within the originals' range (blends of root-relative shapes)
    length = np.linalg.norm(np.diff(a, axis=1), axis=-1).sum(1)
    assert length[s.count:].max() <= length[:s.count].max() * 1.001
    assert d.colors.shape == (1000, 3) and d.widths.shape == (1000,)
    np.testing.assert_array_equal(densify(s, 100, seed=3, n_points=10).points, d.points)  # deterministic
    sub = densify(s, 5, seed=0)
    assert sub.count == 5


def test_densify_to_paper_scale():
    import time

    s = resample(_helix(n_strands=2000, n_points=32), 100)
    t0 = time.perf_counter()
    d = densify(s, 25_000, seed=0)
    elapsed = time.perf_counter() - t0
    assert d.count == 25_000 and len(d.points) == 2_500_000
    print(f"densify 2,000 -> 25,000 strands x 100 points: {elapsed:.2f} s")


def test_bbox_diagonal():
    s = Strands.from_array(np.array([[[0, 0, 0], [3, 4, 0]]], np.float32))
    assert bbox_diagonal(s) == 5.0
