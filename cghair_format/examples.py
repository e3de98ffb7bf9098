"""Small procedurally generated assets for tests, spec vectors and examples (no data files needed).

The geometry is smooth and hair-like (curved cards, strands wandering across them) but is not grown
from a head: for realistic hairstyles use :mod:`cghair_format.synth` and the card builder.
"""

from __future__ import annotations

import numpy as np

from .animation.clip import Animation
from .asset import Appearance, Cards, HairAsset, MlpLayer


def example_asset(seed: int = 0, strands: int = 64, points: int = 16, cards: int = 8, segments: int = 6,
                  groups: int = 2, k: int = 4, latent_dim: int = 8, hidden: int = 16, sh_degree: int = 1,
                  weight_mode: str = "soft") -> HairAsset:
    """A valid :class:`HairAsset` with smooth random geometry and a random appearance model."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, segments + 1)[None, :]
    phase = rng.uniform(0, 2 * np.pi, (cards, 1))
    root = rng.normal(0, 0.05, (cards, 1, 3))
    spine = root + np.stack([0.03 * np.sin(4 * t + phase), -0.3 * t + 0 * phase, 0.03 * np.cos(3 * t + phase)], axis=-1)
    tangent = np.gradient(spine, axis=1)
    normal = np.cross(tangent, np.array([1.0, 0.0, 0.0]))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    half_width = 0.01 + 0.004 * rng.random((cards, 1)) * (1 - 0.5 * t)
    card_set = Cards(spine.astype(np.float32), normal.astype(np.float32), half_width.astype(np.float32),
                     rng.integers(0, groups, cards).astype(np.int32))
    s = np.linspace(0.0, 1.0, points)[None, :]
    strand_card = np.sort(rng.integers(0, cards, strands)).astype(np.int32)
    u = s * rng.uniform(0.85, 1.0, (strands, 1))
    v = np.clip(rng.uniform(0.1, 0.9, (strands, 1)) + 0.08 * np.sin(5 * s + rng.uniform(0, 6, (strands, 1))), 0, 1)
    delta = 0.002 * rng.normal(size=(strands, 1)) * np.sin(3 * s)
    uvd = np.stack([u, v, delta], axis=-1).astype(np.float32)
    opacity = np.clip(0.95 - 0.6 * s[:, 1:] ** 3 + 0.03 * rng.normal(size=(strands, 1)), 0, 1).astype(np.float32)
    out = (points - 1) * (sh_degree + 1) ** 2 * 3
    mlp = [MlpLayer((rng.normal(size=(hidden, latent_dim)) / np.sqrt(latent_dim)).astype(np.float32),
                    (0.1 * rng.normal(size=hidden)).astype(np.float32), "relu"),
           MlpLayer((0.3 * rng.normal(size=(out, hidden)) / np.sqrt(hidden)).astype(np.float32),
                    (0.1 * rng.normal(size=out)).astype(np.float32), "none")]
    appearance = Appearance((2 * rng.normal(size=(strands, k))).astype(np.float32),
                            rng.normal(size=(groups, k, latent_dim)).astype(np.float32), mlp, sh_degree,
                            weight_mode, 1.0)
    return HairAsset(card_set, strand_card, uvd, opacity, appearance, thickness=2e-4, meters_per_unit=1.0,
                     up_axis="Y", generator="cghair examples", attribution="").validate()


def with_interpolated_strands(asset: HairAsset, seed: int = 0) -> HairAsset:
    """``asset`` and as many strands again, each a blend of three strands of one card (random weights
    summing to 1, every other blend resampled at even arc length) placed on that card as a decoder
    places an interpolated strand (spec 4.5): a groom of guides and children."""
    from . import children
    from .geometry import CardMap, bounding_diagonal, strand_points

    rng = np.random.default_rng(seed)
    s = asset.n_strands
    world = strand_points(asset.cards, asset.strand_card, asset.uvd).astype(np.float64)
    first = rng.integers(0, s, s)
    parents = np.array([[f, *rng.choice(np.flatnonzero(asset.strand_card == asset.strand_card[f]), 2)]
                        for f in first], np.int64)
    weights = children.quantize_weights(rng.dirichlet(np.ones(3), s))
    diag = bounding_diagonal(world)
    grown = asset.take_strands(np.r_[np.arange(s), first])
    grown.uvd[s:] = children.place_children(CardMap(asset.cards), 1e-6 * diag, world, parents, weights,
                                            np.arange(s) % 2 == 0, asset.strand_card[first])
    return grown.validate()


def with_point_counts(asset: HairAsset, seed: int = 0) -> HairAsset:
    """``asset`` with each strand cut to its own point count (2..P, random, one strand keeping all ``P``):
    a variable-count asset (spec 3, PCNT). The points past a strand's count stay as they were: the writer
    makes them placeholders."""
    from dataclasses import replace

    rng = np.random.default_rng(seed)
    p = asset.points_per_strand
    counts = rng.integers(2, p + 1, asset.n_strands).astype(np.int32)
    counts[0] = p
    return replace(asset, point_counts=counts).validate()


def example_animation(cards: Cards, frames: int, fps: float = 30.0) -> Animation:
    """``cards`` swung rigidly about their roots, back and forth about x, and bent sideways: a clip whose
    every frame is known exactly (the spec vectors' and the tests' animation)."""
    out = []
    root = cards.spine[:, :1].astype(np.float64)
    along = np.linspace(0, 1, cards.spine.shape[1])[None, :, None]
    for f in range(frames):
        a = 0.4 * np.sin(f / 5)
        c, s = np.cos(a), np.sin(a)
        r = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        spine = (cards.spine - root) @ r.T + root + 0.01 * np.sin(f / 3) * along**2 * np.array([1.0, 0, 0])
        out.append(Cards(spine.astype(np.float32), (cards.normal @ r.T).astype(np.float32), cards.half_width,
                         cards.group))
    return Animation.of_frames(out, fps, start=0.5, source="swing")
