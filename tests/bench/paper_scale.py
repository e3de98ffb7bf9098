"""Paper-scale assets for the benchmarks: real hair from ../shared, resampled (B-spline) to 100
points, densified to 25,000 strands, and built into 800 cards and 64 groups by the card builder.

The card builder gives a default appearance (one-hot logits, a linear MLP that is mostly zeros),
which would flatter the file size. The benchmark swaps in a stand-in with the statistics of a trained
model: K = 10 latents of D = 64 per group, peaked soft logits, a 64 -> 64 -> 99 x 16 x 3 MLP with
Gaussian weights, SH degree 3, and opacities that vary smoothly along each strand and fade at the
tips. Built assets are cached (lossless .cgh) in the pytest cache, keyed by the source file and the
parameters.

Beside it, :func:`trained_paper_scale_asset` reads the trained file `make paper-trained` writes
(harolongo, a Cycles dataset, the latents variant; docs/ablation.md) from ``CGH_PAPER_DATA``
(default ``~/.cache/cghair/paper``), outside the repository like every file derived from ../shared.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hairdata import hair_path

import cghair_format as cgh
from cghair_format.asset import Appearance, HairAsset, MlpLayer
from cghair_format.paper_scale import CARDS, GROUPS, HIDDEN, POINTS, SH_DEGREE, STRANDS, D, K, paper_scale_strands

PAPER_DATA = Path(os.environ.get("CGH_PAPER_DATA", Path.home() / ".cache" / "cghair" / "paper"))
TRAINED = PAPER_DATA / "latents.cgh"  # the Makefile's paper-trained target writes it


def paper_scale_asset(name: str, cache_dir: Path) -> tuple[HairAsset, dict]:
    """The asset built from ``name`` and the card builder's timings (empty when cached)."""
    cached = cache_dir / f"{Path(name).stem}_{STRANDS}x{POINTS}_{CARDS}c{GROUPS}g.cgh"
    if cached.exists():
        return cgh.read(cached), {}
    from cghair_format.cards import build_cards

    strands = paper_scale_strands(hair_path(name))
    build = build_cards(strands, n_cards=CARDS, n_groups=GROUPS, points=POINTS, seed=0, progress=False)
    asset = with_trained_like_appearance(build.asset)
    cgh.write(asset, cached, "lossless")
    return asset, dict(build.timings)


def trained_paper_scale_asset() -> tuple[HairAsset, str]:
    """The trained paper-scale asset and how it was trained; skips, saying how to make it, when absent."""
    if not TRAINED.exists():
        pytest.skip(f"no trained paper-scale file at {TRAINED}: `make paper-trained` makes it (a Cycles dataset "
                    "and 3,000 training iterations, about 85 minutes on 2 cores; CGH_PAPER_DATA moves it)")
    asset = cgh.read(TRAINED)
    iterations = asset.metadata.get("training", {}).get("config", {}).get("iterations", "?")
    return asset, f"trained, {iterations} iterations ({TRAINED})"


def with_trained_like_appearance(asset: HairAsset, seed: int = 0) -> HairAsset:
    rng = np.random.default_rng(seed)
    s, p = asset.n_strands, asset.points_per_strand
    out = (p - 1) * (SH_DEGREE + 1) ** 2 * 3
    logits = rng.normal(size=(s, K))
    logits[np.arange(s), rng.integers(0, K, s)] += 6.0
    mlp = [MlpLayer((rng.normal(size=(HIDDEN, D)) / np.sqrt(D)).astype(np.float32),
                    (0.1 * rng.normal(size=HIDDEN)).astype(np.float32), "relu"),
           MlpLayer((rng.normal(size=(out, HIDDEN)) / np.sqrt(HIDDEN)).astype(np.float32),
                    (0.1 * rng.normal(size=out)).astype(np.float32), "none")]
    asset.appearance = Appearance(logits.astype(np.float32),
                                  rng.normal(size=(asset.appearance.n_groups, K, D)).astype(np.float32),
                                  mlp, SH_DEGREE, "soft", 1.0)
    t = np.linspace(0, 1, p - 1)[None, :]
    asset.opacity = np.clip(0.97 - 0.6 * t**6 + 0.02 * np.sin(6 * t + rng.uniform(0, 6, (s, 1))), 0, 1
                            ).astype(np.float32)
    return asset.validate()
