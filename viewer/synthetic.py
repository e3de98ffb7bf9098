"""A procedural hair asset built in memory, for benchmarks and tests at any scale.

Cards sprout from a head-sized sphere and fall under gravity; strands lie on them with random
across-card offsets and small normal displacements; the appearance model is a random MLP whose
output bias gives a brown base colour. Not meant to look like a hairstyle, only to have the
paper's sizes and a realistic screen footprint.
"""

from __future__ import annotations

import numpy as np

from cghair_format import Appearance, Cards, HairAsset, MlpLayer
from cghair_format.gaussians import rgb_to_sh0

HEAD_RADIUS = 0.1  # scene units (metres)
HAIR_LENGTH = 0.3


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def synthetic_asset(n_strands: int, points: int = 101, strands_per_card: int = 50, segments: int = 8,
                    sh_degree: int = 3, hidden: int = 32, latent_dim: int = 16, k: int = 8,
                    groups: int = 4, seed: int = 0) -> HairAsset:
    """A valid :class:`HairAsset` with ``n_strands`` strands of ``points`` points each."""
    if n_strands < 1 or points < 2:
        raise ValueError(f"need at least 1 strand of 2 points, got {n_strands} x {points}")
    rng = np.random.default_rng(seed)
    n_cards = max(1, n_strands // strands_per_card)
    m1 = segments + 1
    # roots on the upper half of the head; spines grow outward and bend down
    root_dir = _unit(rng.normal(size=(n_cards, 3)) * (1.0, 0.6, 1.0) + (0.0, 0.5, 0.0))
    root_dir[:, 1] = np.abs(root_dir[:, 1])
    t = np.linspace(0.0, 1.0, m1)[None, :, None]
    out = root_dir[:, None, :] * HAIR_LENGTH * 0.4 * np.sin(t * np.pi / 2)
    fall = np.array([0.0, -1.0, 0.0]) * HAIR_LENGTH * t ** 2
    spine = HEAD_RADIUS * root_dir[:, None, :] + out + fall
    tangent = np.gradient(spine, axis=1)
    tangent = _unit(tangent)
    side = _unit(np.cross(tangent, root_dir[:, None, :] + (0.0, 0.0, 1e-3)))
    normal = _unit(np.cross(side, tangent))
    half_width = np.full((n_cards, m1), 0.012) * np.linspace(1.0, 0.6, m1)[None]
    cards = Cards(spine.astype(np.float32), normal.astype(np.float32), half_width.astype(np.float32),
                  rng.integers(0, groups, n_cards).astype(np.int32))

    strand_card = (np.arange(n_strands) % n_cards).astype(np.int32)
    u = np.linspace(0.0, 1.0, points)[None, :]
    v = rng.uniform(0.05, 0.95, (n_strands, 1)) + 0.03 * np.sin(u * 7 + rng.uniform(0, 6, (n_strands, 1)))
    delta = rng.normal(0.0, 0.002, (n_strands, 1)) * np.ones_like(u)
    uvd = np.stack([np.broadcast_to(u, v.shape), np.clip(v, 0, 1), delta], axis=-1).astype(np.float32)
    opacity = rng.uniform(0.4, 1.0, (n_strands, points - 1)).astype(np.float32)

    coeffs = (sh_degree + 1) ** 2
    out_width = (points - 1) * coeffs * 3
    bias = np.zeros((points - 1, coeffs, 3), np.float32)
    bias[:, 0] = rgb_to_sh0(np.array([0.45, 0.3, 0.18]))
    mlp = [MlpLayer(rng.normal(0, 0.3, (hidden, latent_dim)).astype(np.float32),
                    rng.normal(0, 0.1, hidden).astype(np.float32), "relu"),
           MlpLayer(rng.normal(0, 0.02, (out_width, hidden)).astype(np.float32), bias.reshape(-1), "none")]
    appearance = Appearance(rng.normal(0, 1, (n_strands, k)).astype(np.float32),
                            rng.normal(0, 1, (groups, k, latent_dim)).astype(np.float32), mlp, sh_degree)
    asset = HairAsset(cards, strand_card, uvd, opacity, appearance, thickness=4e-4,
                      generator="cghair viewer.synthetic", metadata={"synthetic": True})
    return asset.validate()
