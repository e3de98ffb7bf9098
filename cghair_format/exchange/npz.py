"""NumPy ``.npz`` strands: ``points [N,3]`` + ``offsets [S+1]`` (optional ``colors``, ``widths``,
``meters_per_unit``, ``up_axis``), or a single ``strands [S,P,3]`` array of equal-length strands."""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ..strands import Strands
from ._common import StrandFileError, finish


def load(path: str | Path) -> Strands:
    try:
        with np.load(path, allow_pickle=False) as z:
            _check_sizes(path, z.zip)
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, NotImplementedError) as exc:
        if isinstance(exc, (FileNotFoundError, IsADirectoryError, PermissionError, StrandFileError)):
            raise
        raise StrandFileError(path, f"not a readable .npz archive ({type(exc).__name__}: {exc})") from exc
    try:
        return _strands(path, arrays)
    except (TypeError, ValueError, OverflowError) as exc:  # arrays of the wrong kind or shape
        if isinstance(exc, StrandFileError):
            raise
        raise StrandFileError(path, f"an array has the wrong type or shape ({exc})") from exc


def _check_sizes(path: str | Path, archive: zipfile.ZipFile) -> None:
    """Refuse a member whose .npy header declares more bytes than the member holds, before numpy
    allocates them."""
    for info in archive.infolist():
        with archive.open(info) as f:
            version = np.lib.format.read_magic(f)
            if version not in ((1, 0), (2, 0)):
                raise StrandFileError(path, f"{info.filename}: .npy format version {version} is not supported")
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                np.lib.format.read_array_header_2_0
            shape, _, dtype = read_header(f)
        size = int(np.prod(shape, dtype=object)) * dtype.itemsize
        if size > info.file_size:
            raise StrandFileError(path, f"{info.filename}: its header declares a {shape} {dtype} array "
                                        f"({size:,} bytes), the archive holds {info.file_size:,}")


def _strands(path: str | Path, arrays: dict[str, np.ndarray]) -> Strands:
    for name in ("points", "offsets", "strands", "colors", "widths", "meters_per_unit"):
        if name in arrays and arrays[name].dtype.kind not in "iuf":
            raise StrandFileError(path, f"array {name!r} has dtype {arrays[name].dtype}, not a real number type")
    kw = {}
    if "meters_per_unit" in arrays:
        kw["meters_per_unit"] = float(arrays["meters_per_unit"])
    if "up_axis" in arrays:
        kw["up_axis"] = str(arrays["up_axis"])
    if "points" in arrays and "offsets" in arrays:
        s = Strands(np.asarray(arrays["points"], np.float32), np.asarray(arrays["offsets"], np.int64),
                    _opt(arrays, "colors"), _opt(arrays, "widths"), **kw)
    elif "strands" in arrays and arrays["strands"].ndim == 3 and arrays["strands"].shape[2] == 3:
        s = Strands.from_array(np.asarray(arrays["strands"], np.float32), **kw)
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
