"""Stage 1: strand clustering. k-means on each strand's concatenated resampled points."""

from __future__ import annotations

import numpy as np

from ..errors import require

CLUSTER_POINTS = 25  # points per strand in the k-means feature (75 dims): 4x cheaper than P = 100,
# and at 25 evenly spaced points a strand's shape is still resolved far below the cluster spread.
MAX_ITER = 100


def cluster_features(points: np.ndarray, cluster_points: int = CLUSTER_POINTS) -> np.ndarray:
    """Feature ``[S, 3Q]`` of strands ``[S, P, 3]``: ``Q`` evenly spaced points, concatenated."""
    p = points.shape[1]
    idx = np.unique(np.linspace(0, p - 1, min(cluster_points, p)).round().astype(np.int64))
    return np.ascontiguousarray(points[:, idx].reshape(len(points), -1), dtype=np.float32)


def cluster_strands(points: np.ndarray, n_clusters: int, seed: int = 0,
                    cluster_points: int = CLUSTER_POINTS) -> np.ndarray:
    """Cluster label ``[S]`` of each strand ``[S, P, 3]``, labels ``0..C-1`` with no empty cluster.

    Lloyd k-means with k-means++ seeding and a fixed seed (scikit-learn), so the result is
    deterministic. ``n_clusters`` is capped at the number of distinct strands.
    """
    cluster = require("sklearn.cluster", "cards", "card clustering", package="scikit-learn")
    feats = cluster_features(points, cluster_points)
    n = min(int(n_clusters), len(np.unique(feats, axis=0)))  # no more clusters than distinct strands
    if n <= 1:
        return np.zeros(len(points), np.int32)
    km = cluster.KMeans(n_clusters=n, init="k-means++", n_init=1, max_iter=MAX_ITER,
                        random_state=seed, algorithm="lloyd")
    labels = km.fit_predict(feats)
    # relabel densely, ordered by first strand of each cluster (stable, empty clusters dropped)
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))
    return order[inverse].astype(np.int32)
