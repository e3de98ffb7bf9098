"""Reading a dataset in any layout :func:`.layouts.detect_layout` knows."""

from __future__ import annotations

from pathlib import Path

from .capture import read_capture
from .layouts import detect_layout
from .nerf import read_nerf
from .types import Dataset


def read_dataset(root: str | Path) -> Dataset:
    """Read a dataset in any layout :func:`.layouts.detect_layout` knows: NeRF-synthetic (both
    splits; a missing test split is an error, evaluation needs held-out views), COLMAP or
    GaussianHaircut (:mod:`.capture`)."""
    layout = detect_layout(root)
    return read_nerf(root) if layout.name == "NeRF-synthetic" else read_capture(layout)
