"""Helpers of the card-builder tests: small procedural hair, and the real models in ../shared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cghair_format.strands import Strands

HAIR_DIR = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "hair"
REAL_FILES = ("straight.hair", "harolongo.data", "ruby_long_hair_16_guide.tfx", "Ratboy_mohawk.tfx",
              "Bangs_100.hair", "Bangs_100.data", "Bangs_100_binary.ply", "Bangs_100_ascii.ply",
              "Curly_100.ply")
SMALL_REAL = ("Bangs_100.hair", "Curly_100.ply")

# accuracy targets of the card builder, before quantization, relative to the bounding-box diagonal
MEAN_TARGET = 1e-4
MAX_TARGET = 1e-3
STRIP_TOLERANCE = 1e-3  # v may leave [0, 1] by this much (the builder's own widening tolerance)


def load_real(name: str) -> Strands:
    path = HAIR_DIR / name
    if not path.exists():
        pytest.skip(f"real hair model {name} not found in {HAIR_DIR.resolve()} "
                    "(the ../shared data folder beside the repository; see its PROVENANCE.md)")
    from cghair_format.exchange import load_strands

    return load_strands(path)


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
