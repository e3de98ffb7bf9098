"""Gabor orientation maps: lines at known angles, and splat renders of real strands whose projected
segment directions are known."""

import numpy as np
import pytest
from hairdata import load_hair

from training.reconstruct.orientation import angle_difference, orientation_map, orientation_rgb


def _lines(theta: float, size: int = 64, period: float = 4.0) -> np.ndarray:
    """Bright lines at angle ``theta`` (from +x towards +y), ``period`` pixels apart."""
    y, x = np.mgrid[0:size, 0:size] + 0.5
    v = -x * np.sin(theta) + y * np.cos(theta)
    return (0.5 + 0.5 * np.cos(2 * np.pi * v / period)).astype(np.float32)


@pytest.mark.parametrize("deg", [0, 4, 8, 17, 45, 83, 90, 101.25, 135, 172])
@pytest.mark.parametrize("period", [3, 4, 6])
def test_lines_at_known_angles(deg, period):
    m = orientation_map(_lines(np.radians(deg), period=period))
    inner = (slice(10, -10), slice(10, -10))
    err = np.degrees(angle_difference(m.angle[inner], np.radians(deg)))
    assert np.median(err) < 2.0 and err.max() < 4.0
    assert m.confidence[inner].mean() > 0.5


def test_flat_image_has_no_confidence_and_mask_is_used():
    m = orientation_map(np.full((32, 32), 0.5, np.float32))
    assert m.confidence.max() < 1e-6
    rgba = np.zeros((32, 32, 4), np.float32)
    rgba[..., :3] = _lines(0.3, 32)[..., None]
    rgba[:16, :, 3] = 1.0
    m = orientation_map(rgba)
    assert m.confidence[16:].max() == 0 and m.confidence[4:12, 4:28].min() > 0
    assert orientation_rgb(m).shape == (32, 32, 3)


def _projected_segment_angles(strands, camera, shape, depth):
    """Per pixel: the image angle of the front-most projected strand segment (NaN where none)."""
    from scipy.spatial import cKDTree

    from training.datasets.synthetic import strand_segments

    first, _ = strand_segments(strands)
    a, b = strands.points[first].astype(np.float64), strands.points[first + 1].astype(np.float64)
    t = np.linspace(0, 1, 8)[:, None, None]
    samples = (a[None] * (1 - t) + b[None] * t).reshape(-1, 3)
    uv, z = camera.project(samples)
    uva, _ = camera.project(a)
    uvb, _ = camera.project(b)
    d = uvb - uva
    ang = np.tile(np.arctan2(d[:, 1], d[:, 0]) % np.pi, len(t))
    tree = cKDTree(uv)
    h, w = shape
    py, px = np.mgrid[0:h, 0:w] + 0.5
    near = tree.query_ball_point(np.stack([px.ravel(), py.ravel()], 1), 0.75)
    out = np.full(h * w, np.nan)
    dflat = depth.ravel()
    for i, idx in enumerate(near):
        if idx:
            idx = np.asarray(idx)
            front = idx[np.argmin(z[idx])]
            if abs(z[front] - dflat[i]) < 0.02 * dflat[i]:  # the splat's depth agrees: it is visible
                out[i] = ang[front]
    return out.reshape(h, w)


@pytest.mark.slow
def test_splat_render_of_real_strands_matches_projected_segments():
    from training.datasets.cameras import orbit_cameras
    from training.datasets.synthetic import default_thickness, reference_gaussians
    from training.splatter import render_gaussians

    hair = load_hair("ruby_long_hair_16_guide.tfx")
    sel = np.arange(0, hair.count, 6)  # 500 strands
    from cghair_format.strands import Strands
    strands = Strands.from_array(hair.to_array()[sel].copy(), up_axis=hair.up_axis)
    cam = orbit_cameras(strands.points.astype(np.float64), 4, 128, strands.up_axis)[1]
    thick = default_thickness(strands)
    out = render_gaussians(reference_gaussians(strands, thick), cam)
    a = out["alpha"][..., None]
    rgba = np.concatenate([np.where(a > 1e-6, out["rgb"] / np.maximum(a, 1e-6), 0), a], -1)
    m = orientation_map(rgba)
    depth = out["depth"] / np.maximum(out["alpha"], 1e-6)
    truth = _projected_segment_angles(strands, cam, m.angle.shape, depth)
    sel = np.isfinite(truth) & (m.confidence > 0.3)
    assert sel.sum() > 500
    err = np.degrees(angle_difference(m.angle[sel], truth[sel]))
    print(f"{sel.sum()} pixels: median {np.median(err):.1f} deg, 90th percentile {np.percentile(err, 90):.1f} deg")
    assert np.median(err) < 10.0
