"""Fixtures for the training tests: a small procedural hair cap (no data files needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from hairdata import HAIR_DIR, hair_path
from training_helpers import hair_cap

from cghair_format.exchange import save_strands
from cghair_format.strands import Strands
from training.datasets.synthetic import render_dataset


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


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """80 strands of 10 points and a tiny splatted dataset of them (9 views of 32 x 32), once a module."""
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("tiny")
    strands = hair_cap(80, 10, seed=1)
    render_dataset(strands, root / "ds", views=9, res=32, engine="splat")
    return root, strands
