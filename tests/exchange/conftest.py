"""Fixtures for the interchange tests: the real hair files in ../shared (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cghair_format.strands import Strands

HAIR_DIR = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "hair"

# file -> (strands, min points, max points, total points), from PROVENANCE.md and the files' headers
REAL_FILES = {
    "straight.hair": (10_000, 16, 16, 160_000),
    "harolongo.data": (7_905, 21, 21, 166_005),
    "ruby_long_hair_16_guide.tfx": (3_000, 16, 16, 48_000),
    "Ratboy_mohawk.tfx": (2_228, 32, 32, 71_296),
    "Bangs_100.hair": (100, 5, 21, 1_165),
    "Bangs_100.data": (100, 5, 21, 1_165),
    "Bangs_100_binary.ply": (100, 5, 21, 1_165),
    "Bangs_100_ascii.ply": (100, 5, 21, 1_165),
    "Curly_100.ply": (100, 10, 47, 2_528),
}


def real_file(name: str) -> Path:
    path = HAIR_DIR / name
    if not path.exists():
        pytest.skip(f"real hair data not found at {HAIR_DIR} (it lives in ../shared beside the repository)")
    return path


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
