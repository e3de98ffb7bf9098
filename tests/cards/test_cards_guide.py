import numpy as np
from cards_helpers import sheet

from cghair_format.cards.guide import cluster_centroids, guide_spines, smoothing_spline


def test_centroids_are_cluster_means():
    pts = np.random.default_rng(0).standard_normal((6, 5, 3))
    labels = np.array([0, 1, 0, 1, 1, 2])
    cen = cluster_centroids(pts, labels, 3)
    np.testing.assert_allclose(cen[1], pts[[1, 3, 4]].mean(0))
    np.testing.assert_allclose(cen[2], pts[5])


def test_smoothing_spline_keeps_cubics_and_smooths_noise():
    x = np.linspace(0, 1, 50)
    curve = np.stack([x, x ** 3 - x, 2 * x ** 2], -1)[None]  # a cubic: inside the spline space
    fit = smoothing_spline(curve, segments=16, samples=50)
    np.testing.assert_allclose(fit, curve, atol=1e-9)
    noisy = curve + 0.01 * np.random.default_rng(1).standard_normal(curve.shape)
    err_in = np.abs(noisy - curve).mean()
    err_out = np.abs(smoothing_spline(noisy, segments=16, samples=50) - curve).mean()
    assert err_out < 0.6 * err_in


def test_spines_have_equal_segments_and_cover_roots_and_tips():
    pts = sheet(30, 25, length=4.0)
    pts[::3] += np.array([0, 0.3, 0])  # some strands start later and end beyond the mean tip
    labels = np.zeros(len(pts), np.int64)
    spines, s = guide_spines(pts, labels, 1, segments=10)
    spine = spines[0]
    assert spine.shape == (11, 3)
    seg = np.linalg.norm(np.diff(spine, axis=0), axis=-1)
    np.testing.assert_allclose(seg, seg.mean(), rtol=1e-3)
    t0 = (spine[1] - spine[0]) / seg[0]
    t1 = (spine[-1] - spine[-2]) / seg[-1]
    assert ((pts[:, 0] - spine[0]) @ t0 >= 0).all()  # every root lies beyond the spine start
    assert ((pts[:, -1] - spine[-1]) @ t1 <= 0).all()  # every tip before the spine end


def test_carried_spine_parameter_matches_a_fresh_projection():
    from cards_helpers import synth

    from cghair_format.cards._util import project_to_spines
    from cghair_format.cards.cluster import cluster_strands

    pts = synth("curly", 150, 30).to_array().astype(np.float64)
    labels = cluster_strands(pts, 10)
    spines, s = guide_spines(pts, labels, 10, segments=12)
    fresh = project_to_spines(spines, np.repeat(labels, 30), pts.reshape(-1, 3))
    assert np.median(np.abs(s - fresh)) < 0.05  # in segments: a start guess, not the solution
    assert (np.abs(s - fresh) < 1.0).mean() > 0.95
