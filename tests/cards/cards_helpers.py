"""Helpers of the card-builder tests: small procedural hair, and the real models in ../shared."""

from __future__ import annotations

import numpy as np
from hairdata import load_hair

from cghair_format.strands import Strands

SMALL_REAL = ("Bangs_100.hair", "Curly_100.ply")

# accuracy targets of the card builder, before quantization, relative to the bounding-box diagonal
MEAN_TARGET = 1e-4
MAX_TARGET = 1e-3
STRIP_TOLERANCE = 1e-3  # v may leave [0, 1] by this much (the builder's own widening tolerance)


def load_real(name: str) -> Strands:
    return load_hair(name)


def synth(style: str = "wavy", n: int = 300, points: int = 40, seed: int = 3) -> Strands:
    from cghair_format.synth import synthesize

    return synthesize(style, n, points, seed=seed)


def sheet(n: int = 40, points: int = 30, width: float = 1.0, length: float = 4.0, offplane: float = 0.0,
          seed: int = 0) -> np.ndarray:
    """Strands ``[n, points, 3]`` in the plane z = 0: going along +y, spread across x."""
    rng = np.random.default_rng(seed)
    x = np.linspace(-width / 2, width / 2, n)
    y = np.linspace(0, length, points)
    pts = np.zeros((n, points, 3))
    pts[:, :, 0] = x[:, None] + 0.02 * np.sin(y[None, :] * 2 + rng.uniform(0, 6, (n, 1)))
    pts[:, :, 1] = y[None, :]
    pts[:, :, 2] = offplane * rng.standard_normal((n, 1))
    return pts
