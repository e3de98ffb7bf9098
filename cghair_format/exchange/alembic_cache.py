"""Alembic animated curves (as Blender or Houdini write them), frame by frame, read through Blender.

As for still Alembic grooms (:mod:`.alembic`), Blender (bpy, in its own interpreter) imports the file; it
then writes every frame of the scene's range as a time-sampled, y-up USD stage in a temporary folder,
which :mod:`.usd_cache` reads one frame at a time while the folder lives (as long as the returned cache).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from .strand_cache import StrandCache


def load_cache(path: Path) -> StrandCache:
    """The animated curves of every curves object of the Alembic file ``path``."""
    from .alembic import read_through_usd
    from .usd_cache import load_cache as load_usd

    folder = tempfile.TemporaryDirectory(prefix="cgh_abc_frames_")
    cache = read_through_usd(path, "abc_frames_to_usd", Path(folder.name) / "frames.usdc", load_usd)
    cache.path, cache.folder = str(path), folder
    return cache
