"""Stage 2: guide strands. Each cluster's centroid, fitted with a smoothing B-spline and resampled
to ``M`` card segments of equal arc length, extended so the cluster's roots and tips lie inside."""

from __future__ import annotations

import numpy as np

from ..errors import require
from ._util import normalize, project_to_spines

DENSE_PER_SEGMENT = 8  # spline samples per card segment for the arc-length resampling
END_MARGIN = 0.01  # extra length at each end, as a fraction of the guide's length
COLLAPSED = 0.25  # a cluster's mean strand spanning less than this share of its strands' root-to-tip has collapsed
FOLD_RETRIES = 2  # smoother refits of a folded guide (half the coefficients each), then no extension


def cluster_centroids(points: np.ndarray, labels: np.ndarray, n_clusters: int) -> np.ndarray:
    """Mean strand ``[C, P, 3]`` of each cluster (the k-means centroid in point space)."""
    s, p = points.shape[:2]
    flat = points.reshape(s, -1).astype(np.float64)
    sums = np.zeros((n_clusters, flat.shape[1]))
    np.add.at(sums, labels, flat)
    counts = np.bincount(labels, minlength=n_clusters).astype(np.float64)
    return (sums / np.maximum(counts, 1)[:, None]).reshape(n_clusters, p, 3)


def spline_coefficients(p: int, segments: int) -> int:
    """Coefficients of the smoothing (least-squares) cubic B-spline: what ``M`` segments resolve."""
    return int(min(p, max(4, segments // 2 + 3)))


def bspline_basis(x: np.ndarray, n_coef: int) -> np.ndarray:
    """The design matrix ``[len(x), n_coef]`` of the clamped B-spline of ``n_coef`` coefficients on uniform
    knots over [0, 1] (cubic, or of degree ``n_coef - 1`` below four), at parameters ``x``: constant and
    linear curves are in its span, and it interpolates its end coefficients."""
    interpolate = require("scipy.interpolate", "cards", "B-spline fits", package="scipy")
    degree = min(3, n_coef - 1)
    knots = np.concatenate([np.zeros(degree), np.linspace(0.0, 1.0, n_coef - degree + 1), np.ones(degree)])
    return interpolate.BSpline.design_matrix(np.asarray(x, np.float64), knots, degree).toarray()


def smoothing_spline(centroids: np.ndarray, segments: int, samples: int, n_coef: int | None = None) -> np.ndarray:
    """Least-squares cubic B-spline fits of curves ``[C, P, 3]``, evaluated at ``samples`` points.

    The knots are uniform in the point index (strands are resampled to equal arc length, so their
    mean is close to uniform too), so one design matrix serves every card.
    """
    p = centroids.shape[1]
    n_coef = max(min(n_coef or spline_coefficients(p, segments), p), min(4, p))
    fit = np.linalg.pinv(bspline_basis(np.linspace(0.0, 1.0, p), n_coef))  # [n_coef, P]
    coef = np.einsum("kp,cpd->ckd", fit, centroids)
    return np.einsum("qk,ckd->cqd", bspline_basis(np.linspace(0.0, 1.0, samples), n_coef), coef)


def _resample(dense, arc, t0, t1, before, after, segments: int) -> np.ndarray:
    """Spines ``[C, M+1, 3]`` at equal arc-length steps along the dense curves, extended straight
    along the end tangents by ``before`` / ``after`` (scene units)."""
    length = arc[:, -1]
    spines = np.empty((len(dense), segments + 1, 3))
    for c in range(len(dense)):
        target = np.linspace(-before[c], length[c] + after[c], segments + 1)
        inside = np.clip(target, 0.0, length[c])
        pts = np.stack([np.interp(inside, arc[c], dense[c, :, d]) for d in range(3)], axis=-1)
        pts += np.minimum(target, 0.0)[:, None] * t0[c] + np.maximum(target - length[c], 0.0)[:, None] * t1[c]
        spines[c] = pts
    return spines


def guide_spines(points: np.ndarray, labels: np.ndarray, n_clusters: int, segments: int,
                 show_progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Card spines ``[C, M+1, 3]``: each cluster's smoothed centroid at ``M + 1`` equal arc-length steps.

    Each guide is extended straight along its end tangents so that all of the cluster's points
    project inside it (a strand longer than the mean would otherwise leave its card's strip).
    A guide that folds back on itself (adjacent segments turning by more than 90 degrees, e.g. a
    hooked root extended backwards over itself) is refitted smoother, and finally not extended.
    Also returns each point's spine parameter ``[S * P]`` on its extended spine (segment units):
    its nearest-point projection, carried over by arc length.
    """
    centroids = _uncollapsed(cluster_centroids(points, labels, n_clusters), points, labels)
    p = points.shape[1]
    n_coef = spline_coefficients(p, segments)
    spines, s = _fit(centroids, points, labels, segments, n_coef, True, show_progress)
    for attempt in range(FOLD_RETRIES + 1):
        folded = np.flatnonzero(_folds(spines))
        if len(folded) == 0:
            break
        n_coef = max(4, n_coef // 2)
        extend = attempt < FOLD_RETRIES
        remap = np.full(n_clusters, -1)
        remap[folded] = np.arange(len(folded))
        strands = np.flatnonzero(remap[labels] >= 0)
        sub_spines, sub_s = _fit(centroids[folded], points[strands], remap[labels[strands]], segments,
                                 n_coef, extend, False)
        spines[folded] = sub_spines
        idx = (strands[:, None] * p + np.arange(p)[None, :]).ravel()
        s[idx] = sub_s
    return spines, s


def _chords(curves: np.ndarray) -> np.ndarray:
    """Root-to-tip distances ``[N]`` of curves ``[N, P, 3]``."""
    return np.linalg.norm(curves[:, -1] - curves[:, 0], axis=-1)


def _uncollapsed(centroids: np.ndarray, points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """``centroids`` with each one that its strands cancel out replaced by its member strand nearest it.
    Strands that run every way from a cluster spread over the scalp (one card for a short crop) have
    a mean whose root-to-tip distance is a small share of theirs (:data:`COLLAPSED`): a curve near no
    strand, from which the card could not reach them. Curls cancel too, but along the strands' common
    direction, which the root-to-tip distance keeps."""
    c = len(centroids)
    counts = np.maximum(np.bincount(labels, minlength=c), 1)
    mean_chord = np.bincount(labels, _chords(points), c) / counts
    for k in np.flatnonzero(_chords(centroids) < COLLAPSED * mean_chord):
        members = np.flatnonzero(labels == k)
        far = ((points[members] - centroids[k]) ** 2).sum(axis=(1, 2))
        centroids[k] = points[members[np.argmin(far)]]
    return centroids


def _folds(spines: np.ndarray) -> np.ndarray:
    """Cards ``[C]`` whose spine turns by more than 90 degrees between adjacent segments."""
    d = np.diff(spines, axis=1)
    return ((d[:, 1:] * d[:, :-1]).sum(-1) < 0).any(axis=1)


def _fit(centroids: np.ndarray, points: np.ndarray, labels: np.ndarray, segments: int, n_coef: int,
         extend: bool, show_progress: bool) -> tuple[np.ndarray, np.ndarray]:
    n_clusters = len(centroids)
    dense = smoothing_spline(centroids, segments, DENSE_PER_SEGMENT * segments + 1, n_coef)  # [C, Q, 3]
    t0 = normalize(dense[:, 1] - dense[:, 0])
    t1 = normalize(dense[:, -1] - dense[:, -2])
    arc = np.concatenate([np.zeros((n_clusters, 1)),
                          np.cumsum(np.linalg.norm(np.diff(dense, axis=1), axis=-1), axis=1)], axis=1)
    length = arc[:, -1]
    zero = np.zeros(n_clusters)
    spines = _resample(dense, arc, t0, t1, zero, zero, segments)
    # how far the cluster's points reach beyond each end, along the end segments (strands longer
    # than the mean, and strands that loop back past their root, would leave the strip)
    point_card = np.repeat(labels, points.shape[1])
    s = project_to_spines(spines, point_card, points.reshape(-1, 3), show_progress=show_progress)
    s_min = np.zeros(n_clusters)
    s_max = np.full(n_clusters, float(segments))
    if extend:
        np.minimum.at(s_min, point_card, s)
        np.maximum.at(s_max, point_card, s)
    seg_len = length / segments
    before = -s_min * seg_len + END_MARGIN * length
    after = (s_max - segments) * seg_len + END_MARGIN * length
    spines = _resample(dense, arc, t0, t1, before, after, segments)
    # the same arc-length position on the extended spine (its nodes are equally spaced too)
    total = length + before + after
    s_ext = (s * seg_len[point_card] + before[point_card]) * segments / np.maximum(total[point_card], 1e-300)
    if (length <= 0).any():  # a cluster of zero-length strands: give its card a tiny length
        tiny = 1e-6 * max(float(np.ptp(points.reshape(-1, 3), axis=0).max()), 1e-12)
        for c in np.flatnonzero(length <= 0):
            spines[c] += np.linspace(0.0, tiny, segments + 1)[:, None] * np.array([0.0, 0.0, 1.0])
    return spines, np.clip(s_ext, -1.0, segments + 1.0)
