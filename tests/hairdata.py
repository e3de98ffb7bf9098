"""The real hair models in ../shared/data/hair (beside the repository; see its PROVENANCE.md).

They are never copied into the repository. Tests that need one call :func:`hair_path`, which skips
the test, saying why, on a checkout that has no ../shared.
"""

from __future__ import annotations

from pathlib import Path

import pytest

HAIR_DIR = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "hair").resolve()

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


def hair_path(name: str) -> Path:
    path = HAIR_DIR / name
    if not path.exists():
        pytest.skip(f"real hair model {name} not found in {HAIR_DIR} (the ../shared data folder beside the "
                    "repository; see its PROVENANCE.md)")
    return path


def load_hair(name: str):
    from cghair_format.exchange import load_strands

    return load_strands(hair_path(name))
