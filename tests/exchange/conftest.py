"""Fixtures for the interchange tests: the real hair files in ../shared (skipped when absent)."""

from __future__ import annotations

import numpy as np
import pytest

from cghair_format.strands import Strands


@pytest.fixture
def small_strands() -> Strands:
    """Five strands of different lengths with colours and widths (exactly representable values)."""
    rng = np.random.default_rng(7)
    counts = np.array([2, 5, 9, 3, 7])
    off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    pts = np.cumsum(rng.normal(size=(off[-1], 3)), axis=0).astype(np.float32)
    colors = (rng.integers(0, 256, (off[-1], 3)) / 255).astype(np.float32)
    widths = rng.uniform(0.01, 0.1, off[-1]).astype(np.float32)
    return Strands(pts, off, colors, widths, meters_per_unit=0.01, up_axis="Z")
