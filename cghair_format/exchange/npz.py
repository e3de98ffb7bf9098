"""NumPy ``.npz`` strands: ``points [N,3]`` + ``offsets [S+1]`` (optional ``colors``, ``widths``,
``meters_per_unit``, ``up_axis``), or a single ``strands [S,P,3]`` array of equal-length strands."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ..strands import Strands
from ._common import StrandFileError, finish


def load(path: str | Path) -> Strands:
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise StrandFileError(path, f"not a readable .npz archive ({exc})") from exc
    kw = {}
    if "meters_per_unit" in arrays:
        kw["meters_per_unit"] = float(arrays["meters_per_unit"])
    if "up_axis" in arrays:
        kw["up_axis"] = str(arrays["up_axis"])
    if "points" in arrays and "offsets" in arrays:
        s = Strands(np.asarray(arrays["points"], np.float32), np.asarray(arrays["offsets"], np.int64),
                    _opt(arrays, "colors"), _opt(arrays, "widths"), **kw)
    elif "strands" in arrays and arrays["strands"].ndim == 3 and arrays["strands"].shape[2] == 3:
        s = Strands.from_array(arrays["strands"], **kw)
    else:
        raise StrandFileError(path, f"expected arrays 'points' and 'offsets' (or 'strands' [S,P,3]); "
                                    f"found {sorted(arrays)}")
    if s.up_axis not in ("Y", "Z"):
        raise StrandFileError(path, f"up_axis must be 'Y' or 'Z', got {s.up_axis!r}")
    return finish(path, s)


def _opt(arrays: dict, name: str) -> np.ndarray | None:
    return np.asarray(arrays[name], np.float32) if name in arrays else None


def save(strands: Strands, path: str | Path) -> None:
    arrays = {"points": strands.points.astype(np.float32), "offsets": strands.offsets.astype(np.int64),
              "meters_per_unit": np.float64(strands.meters_per_unit), "up_axis": np.str_(strands.up_axis)}
    if strands.colors is not None:
        arrays["colors"] = strands.colors.astype(np.float32)
    if strands.widths is not None:
        arrays["widths"] = strands.widths.astype(np.float32)
    with atomic_open(path) as f:  # np.savez would append .npz to a path without it
        np.savez_compressed(f, **arrays)
