"""The paper's scale as one recipe: real hair resampled (B-spline) to 100 points and densified to
25,000 strands, built into 800 cards and 64 groups, with the appearance model's sizes (K = 10 latents
of D = 64 per group, one hidden layer of 64, SH degree 3). The benchmarks (tests/bench) and
``python -m training.bench --paper-scale`` both read it from here.
"""

from __future__ import annotations

from pathlib import Path

from .strands import Strands

STRANDS, POINTS, CARDS, GROUPS, K, D, HIDDEN, SH_DEGREE = 25_000, 100, 800, 64, 10, 64, 64, 3


def paper_scale_strands(path: str | Path) -> Strands:
    """The strands of a real model resampled (B-spline) to 100 points and densified to 25,000."""
    from .exchange import load_strands
    from .strands import densify, resample

    return densify(resample(load_strands(path), POINTS, method="bspline"), STRANDS, seed=0)
