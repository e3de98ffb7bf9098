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
