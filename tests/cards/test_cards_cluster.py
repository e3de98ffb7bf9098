import numpy as np
from cards_helpers import sheet, synth

from cghair_format.cards.cluster import cluster_features, cluster_strands


def test_features_take_evenly_spaced_points():
    pts = np.arange(2 * 100 * 3, dtype=np.float32).reshape(2, 100, 3)
    f = cluster_features(pts, 25)
    assert f.shape == (2, 75)
    np.testing.assert_array_equal(f[0, :3], pts[0, 0])
    np.testing.assert_array_equal(f[0, -3:], pts[0, -1])


def test_labels_are_dense_and_capped():
    pts = synth(n=50, points=20).to_array()
    labels = cluster_strands(pts, 8, seed=0)
    assert labels.shape == (50,) and labels.dtype == np.int32
    assert set(labels.tolist()) == set(range(8))
    assert set(cluster_strands(pts, 500).tolist()) == set(range(50))  # capped at the strand count
    assert (cluster_strands(pts[:1], 5) == 0).all()


def test_separated_bundles_are_found():
    a = sheet(20, 20)
    b = sheet(15, 20) + np.array([10.0, 0.0, 0.0])
    c = sheet(10, 20) + np.array([0.0, 0.0, 10.0])
    labels = cluster_strands(np.concatenate([a, b, c]), 3, seed=0)
    groups = [labels[:20], labels[20:35], labels[35:]]
    assert all(len(set(g.tolist())) == 1 for g in groups)
    assert len({int(g[0]) for g in groups}) == 3


def test_deterministic_for_a_seed():
    pts = synth(n=200, points=20).to_array()
    np.testing.assert_array_equal(cluster_strands(pts, 20, seed=4), cluster_strands(pts, 20, seed=4))
