"""Stage 3: card normals and widths.

For each card segment node ``k`` the normal ``n_k`` minimises ``sum_i |(p_i - pbar_k) . n_k|`` over
the cluster points ``p_i`` nearest to that node, subject to ``n_k . t_k = 0`` and ``|n_k| = 1``
(the card plane through the spine that best fits the strands, in the L1 sense, so a few stray
strands do not tilt it). It is solved by Riemannian gradient descent on the circle of admissible
normals, from a card-wide PCA start. Adjacent normals that point opposite ways are flipped, the
normals are smoothed along the card with a Gaussian, re-orthogonalised, and oriented away from the
hair's centre. The half-width ``w_k`` is the largest distance of the node's points along the
bitangent ``b_k = n_k x t_k``, with a margin.
"""

from __future__ import annotations

import numpy as np

from ..errors import require
from ..geometry import spine_tangents
from ._util import any_perpendicular, normalize, progress

GD_ITERATIONS = 60
GD_FIRST_STEP = 0.3  # radians; the step decays geometrically to ~0.002 rad
GD_DECAY = 0.92
L1_SMOOTHING = 0.02  # |x| is smoothed as sqrt(x^2 + eps^2), eps = this x the card's typical offset
NORMAL_SMOOTHING_SIGMA = 1.5  # Gaussian sigma along the card, in spine nodes
WIDTH_MARGIN = 1.05
MIN_HALF_WIDTH = 1e-3  # fraction of the bounding-box diagonal: a one-strand card still has a width


def _card_sums(values: np.ndarray, index: np.ndarray, n: int) -> np.ndarray:
    """``sum`` of ``values [N, D]`` grouped by ``index [N]`` into ``[n, D]`` (bincount per column)."""
    return np.stack([np.bincount(index, weights=values[:, j], minlength=n) for j in range(values.shape[1])], -1)


def orthonormalize(normals: np.ndarray, spine: np.ndarray) -> np.ndarray:
    """Normals made orthogonal to the spine tangents and unit length (any perpendicular if degenerate)."""
    t = spine_tangents(spine)
    n = normals - (normals * t).sum(-1, keepdims=True) * t
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.where(norm > 1e-9, n / np.maximum(norm, 1e-30), any_perpendicular(t))


def consistent_signs(normals: np.ndarray) -> np.ndarray:
    """Flip normals ``[C, M+1, 3]`` along each card so that adjacent ones never point opposite ways
    (the interpolated normal of a segment then never vanishes)."""
    dots = (normals[:, 1:] * normals[:, :-1]).sum(-1)
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=1)
    return normals * np.concatenate([np.ones((len(normals), 1)), flips], axis=1)[..., None]


def card_normals(spine: np.ndarray, points: np.ndarray, card: np.ndarray, s: np.ndarray,
                 hair_centre: np.ndarray, show_progress: bool = False) -> np.ndarray:
    """Unit normals ``[C, M+1, 3]`` orthogonal to the spine tangents (see the module docstring).

    ``points [N, 3]`` are all strand points, ``card [N]`` their card, ``s [N]`` their spine
    parameter (:func:`project_to_spines`).
    """
    ndimage = require("scipy.ndimage", "cards", "card normal smoothing", package="scipy")
    c, m1 = spine.shape[:2]
    t = spine_tangents(spine)  # [C, M+1, 3]
    node = np.clip(np.rint(s), 0, m1 - 1).astype(np.int64)
    flat = card.astype(np.int64) * m1 + node  # node id of each point
    d = points.astype(np.float64) - spine.reshape(-1, 3)[flat]
    tf = t.reshape(-1, 3)[flat]
    d_perp = d - (d * tf).sum(-1, keepdims=True) * tf

    # card-wide start: the bitangent is the direction of largest spread across the spine
    outer = (d_perp[:, :, None] * d_perp[:, None, :]).reshape(-1, 9)
    cov = _card_sums(outer, card, c).reshape(c, 3, 3)
    _, vecs = np.linalg.eigh(cov)
    b_card = vecs[:, :, 2]  # [C, 3]
    n = np.cross(t, b_card[:, None, :])
    n = orthonormalize(n, spine)

    # gradient descent of the (smoothed) L1 objective, each node on its circle of admissible normals
    scale = np.sqrt(np.bincount(card, weights=(d_perp ** 2).sum(-1), minlength=c)
                    / np.maximum(np.bincount(card, minlength=c), 1))
    eps2 = (np.maximum(L1_SMOOTHING * scale, 1e-12) ** 2)[card]
    n_flat = n.reshape(-1, 3)
    t_flat = t.reshape(-1, 3)
    step = GD_FIRST_STEP
    for _ in progress(range(GD_ITERATIONS), "normals", show_progress):
        proj = np.einsum("nc,nc->n", d, n_flat[flat])
        weight = proj / np.sqrt(proj * proj + eps2)
        grad = np.stack([np.bincount(flat, weights=weight * d[:, j], minlength=c * m1) for j in range(3)], -1)
        grad -= (grad * n_flat).sum(-1, keepdims=True) * n_flat
        grad -= (grad * t_flat).sum(-1, keepdims=True) * t_flat
        gnorm = np.linalg.norm(grad, axis=-1, keepdims=True)
        direction = grad / np.maximum(gnorm, 1e-30)
        move = gnorm[:, 0] > 0
        n_flat = np.where(move[:, None], np.cos(step) * n_flat - np.sin(step) * direction, n_flat)
        n_flat = normalize(n_flat)
        step *= GD_DECAY
    n = n_flat.reshape(c, m1, 3)

    # flip adjacent normals that point opposite ways, smooth along the card, re-orthogonalise
    n = consistent_signs(n)
    if m1 > 2:
        n = ndimage.gaussian_filter1d(n, NORMAL_SMOOTHING_SIGMA, axis=1, mode="nearest")
    n = consistent_signs(orthonormalize(n, spine))
    outward = ((spine - hair_centre) * n).sum(-1).sum(-1)
    return n * np.where(outward < 0, -1.0, 1.0)[:, None, None]


def card_half_widths(spine: np.ndarray, normals: np.ndarray, points: np.ndarray, card: np.ndarray,
                     s: np.ndarray, bbox_diagonal: float) -> np.ndarray:
    """Half-widths ``[C, M+1]``: the largest bitangent distance of each node's points, with a margin.

    A node's points are those nearest to it and to its two neighbours; nodes without points take
    the card's widest value.
    """
    c, m1 = spine.shape[:2]
    b = normalize(np.cross(normals, spine_tangents(spine)))
    node = np.clip(np.rint(s), 0, m1 - 1).astype(np.int64)
    flat = card.astype(np.int64) * m1 + node
    dist = np.abs(((points.astype(np.float64) - spine.reshape(-1, 3)[flat]) * b.reshape(-1, 3)[flat]).sum(-1))
    w = np.full(c * m1, -1.0)
    np.maximum.at(w, flat, dist)
    w = w.reshape(c, m1)
    w = np.maximum(np.maximum(w, np.pad(w, ((0, 0), (1, 0)), constant_values=-1)[:, :-1]),
                   np.pad(w, ((0, 0), (0, 1)), constant_values=-1)[:, 1:])
    widest = w.max(axis=1, keepdims=True)
    w = np.where(w < 0, widest, w)
    return np.maximum(w * WIDTH_MARGIN, MIN_HALF_WIDTH * bbox_diagonal)
