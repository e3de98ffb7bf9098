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
        self.message = message


class UnsupportedFormatError(CghError, ValueError):
    """No importer or exporter is registered for a file extension."""


def readable_file(path: str | Path, extensions, what: str) -> tuple[Path, str]:
    """``path`` and its lower-case extension, once the extension is one of ``extensions`` (listed in the
    message in their order) and the file exists; else the one-line error naming ``what`` was to be read."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in extensions:
        raise UnsupportedFormatError(f"{path}: cannot read {what} from {ext or 'a file without extension'}; "
                                     f"known extensions: {', '.join(extensions)}")
    if not p.is_file():
        raise StrandFileError(path, "no such file" if not p.exists() else "not a file")
    return p, ext


def read_bytes(path: str | Path) -> bytes:
    with open(path, "rb") as f:
        return f.read()


def need(path: str | Path, data: bytes, end: int, what: str) -> None:
    """Raise if ``data`` ends before byte ``end`` (where ``what`` should end)."""
    if end > len(data):
        raise StrandFileError(path, f"truncated: {what} needs bytes up to {end}, the file has {len(data)}")


FLOAT32_MAX = float(np.finfo(np.float32).max)
# what Strands calls each field a loader may fill, as messages name it unless the loader says otherwise
FIELDS = {"colors": "colours", "widths": "widths", "meters_per_unit": "units (metres per unit)",
          "root_uv": "root UVs"}


def finish(path: str | Path, strands: Strands, fields: dict[str, str] | None = None) -> Strands:
    """Validate loaded strands, turning an inconsistency into an error that names the file and the field
    (``fields``: the file's own names for :data:`FIELDS`): no strands, a strand without points, a NaN or
    infinite point, arrays that do not fit together, units that are not a positive number, colours that
    are NaN, infinite or negative (those above 1 are clipped), widths that are NaN, infinite, negative
    or zero along a whole strand, root UVs that are NaN or infinite."""
    names = FIELDS | (fields or {})
    if strands.count == 0:
        raise StrandFileError(path, "the file holds no strands")
    try:
        strands.validate()
    except CghError as exc:
        raise StrandFileError(path, str(exc)) from exc
    empty = np.flatnonzero(np.diff(strands.offsets) < 1)
    if len(empty):
        raise StrandFileError(path, f"{len(empty)} strands have no points (the first is strand {int(empty[0])})")
    strands.meters_per_unit = positive(path, names["meters_per_unit"], strands.meters_per_unit)
    for name, shape in (("colors", (len(strands.points), 3)), ("widths", (len(strands.points),))):
        values = getattr(strands, name)
        if values is not None and values.shape != shape:
            raise StrandFileError(path, f"{names[name]}: shape {values.shape}, expected {shape} (one per point)")
    if strands.colors is not None:
        strands.colors = colours(path, names["colors"], strands.colors)
    if strands.widths is not None:
        _check_widths(path, names["widths"], strands.widths, strands.offsets)
    if strands.root_uv is not None and not np.isfinite(strands.root_uv).all():
        bad = ~np.isfinite(strands.root_uv)
        raise StrandFileError(path, f"{names['root_uv']}: {_first_bad(strands.root_uv, bad, 'NaN or infinite')}")
    return strands


def float32(path: str | Path, field: str, values) -> np.ndarray:
    """``values`` as float32, refused (naming ``field``) where any is NaN, infinite or beyond float32's
    range, before the cast would turn it into an infinity (and warn)."""
    v = np.asarray(values)
    if v.dtype == np.float32:
        return v  # NaN and infinities are refused by finish, naming the field
    wide = v.astype(np.float64)
    fits = np.abs(wide) <= FLOAT32_MAX  # False for NaN and infinities too
    if not fits.all():
        raise StrandFileError(path, f"{field}: {_first_bad(wide, ~fits, 'NaN, infinite or beyond float32')}")
    return wide.astype(np.float32)


def positive(path: str | Path, field: str, value) -> float:
    """``value`` as a float, refused (naming ``field``) unless it is a finite number above zero: a unit or a
    scale that is NaN, infinite, zero or negative makes every coordinate meaningless."""
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise StrandFileError(path, f"{field} must be a number, got {value!r}") from exc
    if not (np.isfinite(number) and number > 0):
        raise StrandFileError(path, f"{field} must be a positive finite number, got {number!r}")
    return number


def nonnegative(path: str | Path, field: str, values) -> np.ndarray:
    """``values`` as float64, refused (naming ``field``) where any is NaN, infinite or negative."""
    v = np.asarray(values, np.float64)
    good = np.isfinite(v) & (v >= 0)
    if not good.all():
        raise StrandFileError(path, f"{field}: {_first_bad(v, ~good, 'NaN, infinite or negative')}")
    return v


def colours(path: str | Path, field: str, values: np.ndarray) -> np.ndarray:
    """Colour values as float32 in [0, 1]: refused (naming ``field``) where any is NaN, infinite or
    negative; values above 1 (linear HDR colours) are clipped to 1."""
    return np.minimum(nonnegative(path, field, values), 1.0).astype(np.float32)


def _check_widths(path: str | Path, field: str, widths: np.ndarray, offsets: np.ndarray) -> None:
    """Widths must be finite and >= 0, and above 0 somewhere in every strand (a tip may taper to 0; a
    strand of no width at all is not hair)."""
    w = nonnegative(path, field, widths)
    flat = np.flatnonzero(np.maximum.reduceat(w, offsets[:-1]) <= 0)
    if len(flat):
        raise StrandFileError(path, f"{field}: {len(flat)} strands have zero width at every point (the first is "
                                    f"strand {int(flat[0])})")


def _first_bad(values: np.ndarray, bad: np.ndarray, what: str) -> str:
    """How many entries (rows) of ``values`` are ``bad`` (a mask of their shape), and the first."""
    rows = np.flatnonzero(bad.reshape(len(bad), -1).any(1))
    first = np.asarray(values)[rows[0]]
    return f"{len(rows)} entries hold {what} values (the first is entry {int(rows[0])}: {first.tolist()})"


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
