"""The default, untrained appearance of a freshly built asset.

Per card group, the strands' colour profiles (root RGB, tip RGB) are clustered into ``K`` colours;
codebook entry ``j`` holds profile ``j`` as SH band-0 values in its first 6 dimensions. The MLP is
one linear layer that gives each Gaussian the band-0 colour interpolated from root to tip, all
other SH coefficients 0 (view-independent). Logits are one-hot-like, weights "hard". Strands without
colours get a natural brown with a slight per-strand variation, darker at the root.
"""

from __future__ import annotations

import numpy as np

from ..asset import Appearance, MlpLayer
from ..errors import require
from ..gaussians import rgb_to_sh0

CODEBOOK_SIZE = 10  # K
LATENT_DIM = 64  # D
CHOSEN_LOGIT = 8.0
PROFILE_FRACTION = 0.1  # root / tip colour: mean over the first / last 10% of a strand's points
BROWN_ROOT = np.array([0.22, 0.13, 0.07])
BROWN_TIP = np.array([0.36, 0.23, 0.13])
BROWN_VARIATION = 0.08  # relative per-strand brightness spread
TIP_TAPER_SEGMENTS = 0.05  # the last 5% of segments fade to TIP_OPACITY
TIP_OPACITY = 0.6


def colour_profiles(colors: np.ndarray | None, n_strands: int, seed: int = 0) -> np.ndarray:
    """Root and tip RGB ``[S, 2, 3]`` from per-point colours ``[S, P, 3]``, or brown if none."""
    if colors is not None:
        p = colors.shape[1]
        n = max(1, int(round(PROFILE_FRACTION * p)))
        return np.stack([colors[:, :n].mean(1), colors[:, -n:].mean(1)], axis=1).clip(0, 1)
    rng = np.random.default_rng(seed)
    scale = 1 + BROWN_VARIATION * rng.standard_normal((n_strands, 1, 1))
    hue = 1 + 0.03 * rng.standard_normal((n_strands, 1, 3))
    return (np.stack([BROWN_ROOT, BROWN_TIP])[None] * scale * hue).clip(0, 1)


def profile_codebooks(profiles: np.ndarray, strand_group: np.ndarray, n_groups: int,
                      k: int = CODEBOOK_SIZE, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Per group ``K`` representative profiles ``[N_T, K, 2, 3]`` and each strand's entry ``[S]``."""
    cluster = require("sklearn.cluster", "cards", "default appearance", package="scikit-learn")
    feats = profiles.reshape(len(profiles), 6)
    books = np.zeros((n_groups, k, 6))
    entry = np.zeros(len(profiles), np.int64)
    for g in range(n_groups):
        idx = np.flatnonzero(strand_group == g)
        if len(idx) == 0:
            books[g] = feats.mean(0) if len(feats) else 0.5
            continue
        distinct = len(np.unique(feats[idx].round(4), axis=0))
        if distinct <= k:
            centres, labels = np.unique(feats[idx].round(4), axis=0, return_inverse=True)
            labels = labels.reshape(-1)
        else:
            km = cluster.KMeans(n_clusters=k, init="k-means++", n_init=1, random_state=seed)
            labels = km.fit_predict(feats[idx])
            centres = km.cluster_centers_
        books[g, : len(centres)] = centres
        books[g, len(centres):] = centres[0]
        entry[idx] = labels
    return books.reshape(n_groups, k, 2, 3), entry


def default_appearance(profiles: np.ndarray, strand_group: np.ndarray, n_groups: int, points: int,
                       sh_degree: int = 3, seed: int = 0) -> Appearance:
    """The untrained appearance model (see the module docstring) for strands of ``points`` points."""
    books, entry = profile_codebooks(profiles, strand_group, n_groups, seed=seed)
    codebooks = np.zeros((n_groups, CODEBOOK_SIZE, LATENT_DIM), np.float32)
    codebooks[..., :6] = rgb_to_sh0(books).reshape(n_groups, CODEBOOK_SIZE, 6)
    logits = np.zeros((len(profiles), CODEBOOK_SIZE), np.float32)
    logits[np.arange(len(profiles)), entry] = CHOSEN_LOGIT
    n_seg = points - 1
    coeffs = (sh_degree + 1) ** 2
    weight = np.zeros((n_seg, coeffs, 3, LATENT_DIM), np.float32)
    t = (np.arange(n_seg) + 0.5) / n_seg
    for ch in range(3):
        weight[:, 0, ch, ch] = 1 - t
        weight[:, 0, ch, 3 + ch] = t
    layer = MlpLayer(weight.reshape(n_seg * coeffs * 3, LATENT_DIM),
                     np.zeros(n_seg * coeffs * 3, np.float32), activation="none")
    return Appearance(logits, codebooks, [layer], sh_degree=sh_degree, weight_mode="hard", temperature=1.0)


def default_opacity(n_strands: int, points: int) -> np.ndarray:
    """Opaque segments ``[S, P-1]``, fading slightly over the last few at the tip."""
    n_seg = points - 1
    taper = max(1, int(round(TIP_TAPER_SEGMENTS * n_seg)))
    row = np.ones(n_seg, np.float32)
    if n_seg > taper:
        row[-taper:] = np.linspace(1.0, TIP_OPACITY, taper + 1, dtype=np.float32)[1:]
    return np.broadcast_to(row, (n_strands, n_seg)).copy()


def default_thickness(points: np.ndarray, widths: np.ndarray | None) -> float:
    """Gaussian radius ``d``: half the median input width, else a third of the typical spacing
    between neighbouring strands (measured at their mid points)."""
    if widths is not None and np.isfinite(widths).all() and (widths > 0).any():
        return float(np.median(widths[widths > 0]) / 2)
    spatial = require("scipy.spatial", "cards", "strand spacing", package="scipy")
    mid = points[:, points.shape[1] // 2].astype(np.float64)
    if len(mid) < 2:
        return float(max(np.linalg.norm(np.ptp(points.reshape(-1, 3), axis=0)) * 1e-3, 1e-6))
    dist, _ = spatial.cKDTree(mid).query(mid, k=2)
    spacing = float(np.median(dist[:, 1]))
    if spacing <= 0:
        spacing = float(np.linalg.norm(np.ptp(points.reshape(-1, 3), axis=0))) * 1e-3
    return max(spacing / 3, 1e-9)
