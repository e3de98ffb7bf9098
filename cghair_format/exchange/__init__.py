"""Strand interchange: load and save strands in other tools' formats, chosen by file extension.

Like trimesh's ``exchange``: one module per format, each registered below by extension.
Loaders return :class:`~cghair_format.strands.Strands`; units and up axis are set only where the
format states them (override with ``units=`` / ``up=``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..strands import Strands
from ._common import StrandFileError, UnsupportedFormatError
from .cgh_strands import strands_from_asset
from .ply_3dgs import read_3dgs_ply, write_3dgs_ply
from .usd_export import export_gaussians_usd, export_usd

# extension -> module (relative to this package) with load(path, **options) and optionally save(strands, path)
FORMATS: dict[str, str] = {
    ".hair": "hair",
    ".data": "usc_data",
    ".tfx": "tfx",
    ".ply": "ply_strands",
    ".usd": "usd_curves",
    ".usda": "usd_curves",
    ".usdc": "usd_curves",
    ".usdz": "usd_curves",
    ".npz": "npz",
    ".cgh": "cgh_strands",
    ".abc": "alembic",  # through Blender (bpy) in a subprocess
}
# formats a loader accepts but that cannot be written
READ_ONLY: set[str] = {".cgh"}
UP_AXES = ("Y", "Z")

__all__ = ["FORMATS", "StrandFileError", "UnsupportedFormatError", "export_gaussians_usd", "export_usd",
           "load_strands", "read_3dgs_ply", "readable_extensions", "save_strands", "strands_from_asset",
           "writable_extensions", "write_3dgs_ply"]


def _module(path: str | Path, for_writing: bool):
    ext = Path(path).suffix.lower()
    if ext not in FORMATS or (for_writing and ext in READ_ONLY):
        allowed = writable_extensions() if for_writing else readable_extensions()
        verb = "write" if for_writing else "read"
        raise UnsupportedFormatError(f"{path}: cannot {verb} strands as {ext or 'a file without extension'}; "
                                     f"known extensions: {', '.join(allowed)}")
    return importlib.import_module(f"{__name__}.{FORMATS[ext]}")


def readable_extensions() -> list[str]:
    return sorted(FORMATS)


def writable_extensions() -> list[str]:
    return sorted(set(FORMATS) - READ_ONLY)


def load_strands(path: str | Path, *, units: float | None = None, up: str | None = None,
                 points_per_strand: int | None = None) -> Strands:
    """Load strands from any registered format (``.hair .data .tfx .ply .usd* .npz .cgh .abc``).

    ``units`` (metres per unit) and ``up`` ("Y" or "Z") override what the file says or the
    defaults; ``points_per_strand`` splits vertex-only strand PLY files.
    """
    mod = _module(path, for_writing=False)
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(2, "No such file or directory", str(p))
    if p.is_dir():
        raise IsADirectoryError(21, "Is a directory", str(p))
    load: Callable = mod.load
    if mod.__name__.endswith("ply_strands"):
        strands = load(p, points_per_strand=points_per_strand)
    else:
        strands = load(p)
    return override(strands, units=units, up=up)


def override(strands: Strands, *, units: float | None = None, up: str | None = None) -> Strands:
    """Set metres-per-unit and up axis where given (the CLI's ``--units`` / ``--up``)."""
    if units is not None:
        if not (np.isfinite(units) and units > 0):
            raise UnsupportedFormatError(f"units (metres per unit) must be positive, got {units}")
        strands.meters_per_unit = float(units)
    if up is not None:
        if up.upper() not in UP_AXES:
            raise UnsupportedFormatError(f"up axis must be one of {UP_AXES}, got {up!r}")
        strands.up_axis = up.upper()
    return strands


def save_strands(strands: Strands, path: str | Path) -> None:
    """Write strands in the format named by ``path``'s extension."""
    mod = _module(path, for_writing=True)
    strands.validate()
    mod.save(strands, Path(path))
