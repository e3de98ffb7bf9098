"""Alembic animated curves (as Blender or Houdini write them), frame by frame, read through Blender.

As for still Alembic grooms (:mod:`.alembic`), Blender (bpy, in its own interpreter) imports the file; it
then writes every frame of the scene's range as a time-sampled, y-up USD stage in a temporary folder,
which :mod:`.usd_cache` reads one frame at a time while the folder lives (as long as the returned cache).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from ._common import StrandFileError
from .strand_cache import StrandCache


def load_cache(path: Path) -> StrandCache:
    """The animated curves of every curves object of the Alembic file ``path``."""
    from .alembic import BlenderRunError, run_worker
    from .usd_cache import load_cache as load_usd

    folder = tempfile.TemporaryDirectory(prefix="cgh_abc_frames_")
    usd = Path(folder.name) / "frames.usdc"
    try:
        run_worker("abc_frames_to_usd", path.resolve(), usd)
    except BlenderRunError as exc:
        raise StrandFileError(path, str(exc)) from exc
    try:
        cache = load_usd(usd)
    except StrandFileError as exc:  # name the Alembic file, not Blender's temporary stage
        raise StrandFileError(path, exc.message) from exc
    cache.path, cache.folder = str(path), folder
    return cache
