"""Stage 5: strand textures and card groups.

Each card's strands, as curves in the card's UV space, are fitted with least-squares cubic
B-splines, sampled densely and splatted with bilinear (anti-aliased) weights into a small coverage
image (rows along ``u``, columns across ``v``). The images, box-filtered to a smaller size, are the
cards' features; k-means on them gives the ``N_T`` card groups that share a codebook.
"""

from __future__ import annotations

import numpy as np

from ..errors import require
from .guide import bspline_basis

TEXTURE_SIZE = 32  # texels along u and across v
SAMPLES_PER_POINT = 2  # dense samples per strand point ...
SAMPLES_PER_ROW = 8  # ... and at least this many per texel row (even deposits along a strand)
FEATURE_SIZE = 16  # the feature is the texture box-filtered to FEATURE_SIZE x FEATURE_SIZE
SPLINE_COEFFICIENTS = 12


def uv_splines(uv: np.ndarray, samples: int) -> np.ndarray:
    """Least-squares cubic B-spline fits of UV curves ``[S, P, 2]``, sampled at ``samples`` points."""
    p = uv.shape[1]
    n_coef = min(SPLINE_COEFFICIENTS, p)
    basis = bspline_basis(np.linspace(0, 1, p), n_coef)
    resample = bspline_basis(np.linspace(0, 1, samples), n_coef) @ np.linalg.pinv(basis)  # [samples, P]
    return np.einsum("qp,spd->sqd", resample, uv)


def strand_textures(uv: np.ndarray, strand_card: np.ndarray, n_cards: int,
                    size: int = TEXTURE_SIZE, counts: np.ndarray | None = None) -> np.ndarray:
    """Coverage images ``[C, size, size]`` in [0, 1] of each card's strands (``uv [S, P, 2]``; a strand
    of ``counts[s] < P`` points is its first ``counts[s]``, the rest placeholders).

    A strand crossing a texel row adds ~1 to the row's texels, split bilinearly between neighbours.
    """
    p = uv.shape[1]
    counts = np.full(len(uv), p) if counts is None else np.asarray(counts)
    samples = max(SAMPLES_PER_POINT * p, SAMPLES_PER_ROW * size)
    curves = np.empty((len(uv), samples, 2))  # [S, Q, 2]
    for n in np.unique(counts):  # strands of one count share a spline fit over their own points
        rows = counts == n
        curves[rows] = uv_splines(uv[rows, :n].astype(np.float64), samples)
    np.clip(curves, 0.0, 1.0, out=curves)
    y = curves[..., 0] * (size - 1)
    x = curves[..., 1] * (size - 1)
    y0 = np.minimum(np.floor(y), size - 2).astype(np.int64)
    x0 = np.minimum(np.floor(x), size - 2).astype(np.int64)
    fy, fx = y - y0, x - x0
    base = strand_card.astype(np.int64)[:, None] * size * size
    total = n_cards * size * size
    image = np.zeros(total)
    weight = size / samples  # so that one strand deposits ~1 per texel row it crosses
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            idx = base + (y0 + dy) * size + (x0 + dx)
            image += np.bincount(idx.ravel(), weights=(wy * wx).ravel() * weight, minlength=total)
    return np.clip(image.reshape(n_cards, size, size), 0.0, 1.0).astype(np.float32)


def texture_features(textures: np.ndarray, size: int = FEATURE_SIZE) -> np.ndarray:
    """Box-filtered textures, flattened: ``[C, size * size]``."""
    c, h, w = textures.shape
    fy, fx = max(h // size, 1), max(w // size, 1)
    small = textures[:, : (h // fy) * fy, : (w // fx) * fx].reshape(c, h // fy, fy, w // fx, fx).mean((2, 4))
    return small.reshape(c, -1)


def card_groups(textures: np.ndarray, n_groups: int, seed: int = 0) -> np.ndarray:
    """Card group ``[C]`` in ``0..N_T-1`` (no empty group): k-means on the texture features."""
    cluster = require("sklearn.cluster", "cards", "card grouping", package="scikit-learn")
    feats = texture_features(textures).astype(np.float64)
    n = min(int(n_groups), len(np.unique(feats, axis=0)))  # no more groups than distinct textures
    if n <= 1:
        return np.zeros(len(textures), np.int32)
    km = cluster.KMeans(n_clusters=n, init="k-means++", n_init=4, random_state=seed)
    labels = km.fit_predict(feats)
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    return np.argsort(np.argsort(first))[inverse].astype(np.int32)
