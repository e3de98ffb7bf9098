"""Shared pieces of the strand importers: the error type and size checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import CghError
from ..strands import Strands


class StrandFileError(CghError, ValueError):
    """A strand file is truncated or malformed; the message names the file and what is wrong."""

    def __init__(self, path: str | Path, message: str):
        super().__init__(f"{path}: {message}")
        self.path = str(path)


class UnsupportedFormatError(CghError, ValueError):
    """No importer or exporter is registered for a file extension."""


def read_bytes(path: str | Path) -> bytes:
    with open(path, "rb") as f:
        return f.read()


def need(path: str | Path, data: bytes, end: int, what: str) -> None:
    """Raise if ``data`` ends before byte ``end`` (where ``what`` should end)."""
    if end > len(data):
        raise StrandFileError(path, f"truncated: {what} needs bytes up to {end}, the file has {len(data)}")


def finish(path: str | Path, strands: Strands) -> Strands:
    """Validate loaded strands, turning an inconsistency into an error that names the file: no strands, a
    strand without points, a NaN or infinite point, colour or width, arrays that do not fit together."""
    if strands.count == 0:
        raise StrandFileError(path, "the file holds no strands")
    try:
        strands.validate()
    except CghError as exc:
        raise StrandFileError(path, str(exc)) from exc
    empty = np.flatnonzero(np.diff(strands.offsets) < 1)
    if len(empty):
        raise StrandFileError(path, f"{len(empty)} strands have no points (the first is strand {int(empty[0])})")
    for name, shape in (("colors", (len(strands.points), 3)), ("widths", (len(strands.points),))):
        values = getattr(strands, name)
        if values is not None and values.shape != shape:
            raise StrandFileError(path, f"point {name} have shape {values.shape}, expected {shape}")
        if values is not None and not np.isfinite(values).all():
            raise StrandFileError(path, f"point {name} contain NaN or infinite values")
    return strands


def offsets_from_counts(counts: np.ndarray) -> np.ndarray:
    off = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=off[1:])
    return off


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB display values in [0, 1] to linear (the IEC 61966-2-1 transfer function)."""
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear values in [0, 1] to sRGB display values (inverse of :func:`srgb_to_linear`)."""
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055).astype(np.float32)


def check_scale(scale: float) -> float:
    """An export scale (output units per input unit) must be a positive finite number."""
    if not (np.isfinite(scale) and scale > 0):
        raise UnsupportedFormatError(f"export scale must be a positive number, got {scale}")
    return float(scale)


def scale_strands(strands: Strands, scale: float) -> Strands:
    """``strands`` with coordinates and widths multiplied by ``scale`` and the metres per unit
    divided by it, so the hair keeps its real size (``scale=100`` on metres gives centimetres)."""
    scale = check_scale(scale)
    if scale == 1.0:
        return strands
    widths = None if strands.widths is None else (strands.widths * scale).astype(np.float32)
    return Strands((strands.points * scale).astype(np.float32), strands.offsets, strands.colors, widths,
                   meters_per_unit=strands.meters_per_unit / scale, up_axis=strands.up_axis,
                   root_uv=strands.root_uv)


def warn(message: str) -> None:
    """One clean line on stderr (``cgh: warning: ...``), not a Python warning with a source line."""
    import sys

    print(f"cgh: warning: {message}", file=sys.stderr)
