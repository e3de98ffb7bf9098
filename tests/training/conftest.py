"""Fixtures for the training tests: a small procedural hair cap (no data files needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hairdata import HAIR_DIR, hair_path
from training_helpers import hair_cap

from cghair_format.strands import Strands


@pytest.fixture
def strands() -> Strands:
    return hair_cap()


@pytest.fixture
def hair_dir() -> Path:
    hair_path("")  # skips, saying why, where ../shared is absent
    return HAIR_DIR
