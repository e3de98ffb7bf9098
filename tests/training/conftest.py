"""Fixtures for the training tests: a small procedural hair cap (no data files needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hairdata import HAIR_DIR, hair_path
from training_helpers import hair_cap

from cghair_format.exchange import save_strands
from cghair_format.strands import Strands


@pytest.fixture
def strands() -> Strands:
    return hair_cap()


@pytest.fixture
def strands_file(tmp_path, strands) -> Path:
    """The hair cap saved as .npz, for the command-line tests."""
    path = tmp_path / "cap.npz"
    save_strands(strands, path)
    return path


@pytest.fixture
def hair_dir() -> Path:
    hair_path("")  # skips, saying why, where ../shared is absent
    return HAIR_DIR
