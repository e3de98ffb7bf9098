"""NumPy ``.npz`` strands: ``points [N,3]`` + ``offsets [S+1]`` (optional ``colors``, ``widths``,
``meters_per_unit``, ``up_axis``), or a single ``strands [S,P,3]`` array of equal-length strands."""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ..limits import ReadLimits, default_limits
from ..strands import Strands
from ._common import StrandFileError, finish

# the arrays a strand .npz may hold, and how many values each holds per point at most (offsets: per strand,
# and strands have a point at least); other members are not read
MEMBERS = {"points": 3, "offsets": 1, "strands": 3, "colors": 3, "widths": 1, "meters_per_unit": 0, "up_axis": 0}
NUMERIC = "iuf"  # the dtype kinds of every member but up_axis
MAX_TEXT = 64  # bytes of up_axis's string dtype


def load(path: str | Path) -> Strands:
    try:
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:  # our handle: closed on a bad zip too
            names = [name for name in z.files if name in MEMBERS]
            _check_sizes(path, z.zip, default_limits())
            arrays = {name: z[name] for name in names}
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


def _check_sizes(path: str | Path, archive: zipfile.ZipFile, limits: ReadLimits) -> None:
    """Refuse, before numpy inflates a byte of their data, members (of :data:`MEMBERS`) that the reader's
    ``limits`` do not allow: more values than ``max_gaussians`` points hold (each point becomes about one
    Gaussian), more bytes in all than ``max_decoded_bytes`` (the central directory's sizes), an .npy header
    that declares more bytes than its member holds, or a dtype the array cannot have. Only the central
    directory and each member's first few kilobytes (its .npy header) are read."""
    members = [info for info in archive.infolist() if info.filename.removesuffix(".npy") in MEMBERS]
    total = sum(info.file_size for info in members)
    if total > limits.max_decoded_bytes:
        raise StrandFileError(path, f"its arrays inflate to {total:,} bytes, more than this reader's limit of "
                                    f"{limits.max_decoded_bytes:,} (raise it with cgh --max-decoded-mb M)")
    for info in members:
        name = info.filename.removesuffix(".npy")
        shape, dtype = _header(path, archive, info)
        text = name == "up_axis"
        if not (dtype.kind in "US" and dtype.itemsize <= MAX_TEXT if text else dtype.kind in NUMERIC):
            raise StrandFileError(path, f"array {name!r} has dtype {dtype}, not "
                                        f"{'a short string' if text else 'a real number type'}")
        count = int(np.prod(shape, dtype=object))
        most = MEMBERS[name] * limits.max_gaussians + 1
        if MEMBERS[name] == 0 and count != 1:
            raise StrandFileError(path, f"array {name!r} must hold one value, it declares shape {shape}")
        if count > most:
            raise StrandFileError(path, f"array {name!r} declares {count:,} values, more than the {most:,} that "
                                        f"this reader's limit of {limits.max_gaussians:,} points allows "
                                        "(raise it with cgh --max-gaussians N)")
        if count * dtype.itemsize > info.file_size:
            raise StrandFileError(path, f"{info.filename}: its header declares a {shape} {dtype} array "
                                        f"({count * dtype.itemsize:,} bytes), the archive holds {info.file_size:,}")


def _header(path: str | Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> tuple[tuple, np.dtype]:
    """The shape and dtype a member's .npy header declares (inflating only the header's bytes)."""
    with archive.open(info) as f:
        version = np.lib.format.read_magic(f)
        if version not in ((1, 0), (2, 0)):
            raise StrandFileError(path, f"{info.filename}: .npy format version {version} is not supported")
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
            np.lib.format.read_array_header_2_0
        shape, _, dtype = read_header(f)
    return shape, dtype


def _strands(path: str | Path, arrays: dict[str, np.ndarray]) -> Strands:
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
    return finish(path, s, {name: f"array {name!r}" for name in ("colors", "widths", "meters_per_unit")})


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
