"""Helpers of the training tests: a small procedural hair cap (no data files needed)."""

from __future__ import annotations

import numpy as np

from cghair_format.strands import Strands


def hair_cap(n_strands: int = 120, n_points: int = 12, seed: int = 0) -> Strands:
    """Strands rooted on the upper half of a unit sphere, falling down and outwards with a wave."""
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0, 2 * np.pi, n_strands)
    phi = rng.uniform(0.0, 1.1, n_strands)  # from the top of the head
    root = np.stack([np.sin(phi) * np.cos(theta), np.cos(phi), np.sin(phi) * np.sin(theta)], -1)
    t = np.linspace(0, 1, n_points)[None, :, None]
    out = root * np.array([1.0, 0.0, 1.0])
    out /= np.maximum(np.linalg.norm(out, axis=-1, keepdims=True), 1e-6)
    wave = 0.05 * np.sin(6 * t + theta[:, None, None])
    pts = root[:, None] * (1 + 0.15 * t) + out[:, None] * (0.3 * t + wave) + np.array([0, -1.0, 0]) * 1.2 * t ** 2
    return Strands.from_array(pts.astype(np.float32))
