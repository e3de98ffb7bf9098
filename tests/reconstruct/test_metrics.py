"""Strand metrics on crafted strands: identical, shifted, rotated, partial, curved."""

import numpy as np
import pytest

from cghair_format.strands import Strands
from training.reconstruct.metrics import StrandMetricsError, evaluate_strands, sample_strands


def _parallel(n=20, length=0.1, spacing=0.01, points=11, axis=(0, 0, 1)) -> Strands:
    """``n`` straight strands in metres, roots on a line along x, ``spacing`` apart."""
    t = np.linspace(0, length, points)
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    pts = np.stack([np.array([i * spacing, 0, 0]) + t[:, None] * axis for i in range(n)])
    return Strands.from_array(pts.astype(np.float32))


def test_identical_strands_score_one():
    s = _parallel()
    m = evaluate_strands(s, s)
    assert m.position_error_mm == pytest.approx(0, abs=1e-6)
    assert m.curvature_error == pytest.approx(0, abs=1e-6)
    assert all(sc["f1"] == 1.0 for sc in m.scores)


def test_shift_beyond_the_threshold_gives_zero():
    gt = _parallel()
    recon = Strands(gt.points + np.float32([0, 0.005, 0]), gt.offsets)  # 5 mm sideways
    m = evaluate_strands(recon, gt)
    assert m.position_error_mm == pytest.approx(5.0, abs=1e-3)
    assert m.f1(4.0) == 0.0
    shifted = Strands(gt.points + np.float32([0, 0.0025, 0]), gt.offsets)  # 2.5 mm: inside 3 and 4 mm only
    m = evaluate_strands(shifted, gt)
    assert (m.f1(2.0), m.f1(3.0), m.f1(4.0)) == (0.0, 1.0, 1.0)


def test_rotated_directions_fail_the_angle():
    gt = _parallel(n=1, length=0.002, points=3)  # a 2 mm strand
    for deg, expected in ((10, (1, 1, 1)), (25, (0, 1, 1)), (35, (0, 0, 1)), (45, (0, 0, 0))):
        a = np.radians(deg)
        recon = _parallel(n=1, length=0.002, points=3, axis=(np.sin(a), 0, np.cos(a)))
        m = evaluate_strands(recon, gt, step_mm=0.1)
        # points near the shared root are close; the angle alone decides
        assert tuple(int(s["precision"] > 0) for s in m.scores) == expected, deg


def test_directions_are_undirected():
    gt = _parallel()
    flipped = Strands.from_array(gt.to_array()[:, ::-1].copy())
    assert evaluate_strands(flipped, gt).f1(2.0) == 1.0


def test_partial_reconstruction_has_full_precision_and_half_recall():
    gt = _parallel(n=20, spacing=0.02)  # 20 mm apart: a strand never matches its neighbour
    recon = Strands.from_array(gt.to_array()[:10].copy())
    m = evaluate_strands(recon, gt)
    assert m.scores[0]["precision"] == 1.0
    assert m.scores[0]["recall"] == pytest.approx(0.5, abs=0.01)
    assert m.position_error_mm == pytest.approx(0, abs=1e-6)
    assert m.position_error_gt_mm > 50


def test_curvature_of_a_circle():
    r = 0.05  # 5 cm: curvature 20 / m
    t = np.linspace(0, np.pi, 2000)
    arc = np.stack([r * np.cos(t), r * np.sin(t), 0 * t], 1)[None].astype(np.float32)
    sampled = sample_strands(Strands.from_array(arc))
    assert np.median(sampled.curvature) == pytest.approx(20.0, rel=0.02)
    straight = Strands.from_array(np.stack([t * 0.05 / np.pi, 0 * t, 0 * t], 1)[None].astype(np.float32))
    m = evaluate_strands(straight, Strands.from_array(arc))
    assert m.curvature_error == pytest.approx(20.0, rel=0.05)


def test_units_are_converted_and_overridable():
    gt = _parallel()
    cm = Strands(gt.points * 100, gt.offsets, meters_per_unit=0.01)
    shifted = Strands((gt.points + np.float32([0, 0.0025, 0])) * 100, gt.offsets, meters_per_unit=0.01)
    assert evaluate_strands(shifted, cm).position_error_mm == pytest.approx(2.5, abs=1e-3)
    # declared as metres, the same numbers are 100 x further apart
    assert evaluate_strands(shifted, cm, meters_per_unit=1.0).position_error_mm == pytest.approx(250, rel=1e-3)


def test_resampling_spacing_is_the_step():
    s = sample_strands(_parallel(n=2, length=0.1, points=4), step_mm=1.0)
    assert len(s.points) == 2 * 101
    gaps = np.linalg.norm(np.diff(s.points[:101], axis=0), axis=1)
    assert np.allclose(gaps, 1.0)


def test_dense_neighbourhoods_find_the_aligned_point_beyond_k():
    # 40 crossing strands at 90 deg around one aligned strand: the aligned one is not among the 16 nearest
    t = np.linspace(-0.002, 0.002, 41)
    cross = [np.stack([0 * t + dx, t, 0 * t], 1) for dx in np.linspace(-0.0005, 0.0005, 40)]
    aligned = np.stack([t, 0 * t, 0 * t + 0.0015], 1)
    gt = Strands.from_array(np.stack(cross + [aligned]).astype(np.float32))
    recon = Strands.from_array(np.stack([t, 0 * t, 0 * t], 1)[None].astype(np.float32))
    m = evaluate_strands(recon, gt, step_mm=0.1)
    assert m.scores[0]["precision"] == pytest.approx(1.0)


def test_empty_strands_are_refused():
    empty = Strands(np.zeros((0, 3), np.float32), np.zeros(1, np.int64))
    with pytest.raises(StrandMetricsError, match="no strands"):
        evaluate_strands(empty, _parallel())
