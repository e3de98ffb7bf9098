"""Typed arrays inside a chunk payload (spec: "Array records").

A record is ``u8 dtype, u8 ndim, u16 flags, u32 dims[ndim]`` then the little-endian elements.
Flag bit 0: the elements are byte-shuffled (all first bytes, then all second bytes, ...), which lets
zstd see the mostly-zero high bytes of small integers as long runs. Flag bit 1: the unsigned
elements are zigzag-coded signed integers.
"""

from __future__ import annotations

import struct

import numpy as np

from .errors import InvalidContentError, TruncatedError
from .quantize import unzigzag, zigzag

DTYPES = {1: "<u1", 2: "<i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<f2", 9: "<f4"}
CODES = {np.dtype(v).str: k for k, v in DTYPES.items()}
SHUFFLED, ZIGZAG = 1, 2
MAX_NDIM = 4


class StreamWriter:
    def __init__(self) -> None:
        self._parts: list[bytes] = []

    def array(self, a: np.ndarray, shuffle: bool = False, _flags: int = 0) -> None:
        a = np.ascontiguousarray(a)
        a = a.astype(a.dtype.newbyteorder("<"), copy=False)
        code = CODES[a.dtype.str]
        flags = _flags | (SHUFFLED if shuffle and a.itemsize > 1 else 0)
        head = struct.pack("<BBH", code, a.ndim, flags) + struct.pack(f"<{a.ndim}I", *a.shape)
        data = a.view(np.uint8).reshape(-1, a.itemsize).T.tobytes() if flags & SHUFFLED else a.tobytes()
        self._parts.append(head + data)

    def ints(self, a: np.ndarray) -> None:
        """Signed integers, zigzag-coded into the narrowest unsigned type, byte-shuffled."""
        u = zigzag(np.asarray(a))
        top = int(u.max()) if u.size else 0
        dtype = next(t for t in (np.uint8, np.uint16, np.uint32, np.uint64) if top <= np.iinfo(t).max)
        self.array(u.astype(dtype), shuffle=True, _flags=ZIGZAG)

    def getvalue(self) -> bytes:
        return b"".join(self._parts)


class StreamReader:
    """Reads records in order, checking each against the shape the decoder expects."""

    def __init__(self, data: bytes, chunk: str) -> None:
        self._data = memoryview(data)
        self._pos = 0
        self.chunk = chunk

    def _fail(self, message: str, kind=InvalidContentError):
        raise kind(message, chunk=self.chunk, offset=self._pos)

    def array(self, shape: tuple[int | None, ...], name: str, dtypes: tuple[str, ...] | None = None) -> np.ndarray:
        if self._pos + 4 > len(self._data):
            self._fail(f"array {name!r} is missing: the payload ends early", TruncatedError)
        code, ndim, flags = struct.unpack_from("<BBH", self._data, self._pos)
        if code not in DTYPES or ndim > MAX_NDIM or flags & ~(SHUFFLED | ZIGZAG):
            self._fail(f"array {name!r} has a bad record header (dtype {code}, ndim {ndim}, flags {flags})")
        if self._pos + 4 + 4 * ndim > len(self._data):
            self._fail(f"array {name!r} header runs past the payload", TruncatedError)
        dims = struct.unpack_from(f"<{ndim}I", self._data, self._pos + 4)
        if len(dims) == len(shape):  # a None in ``shape`` takes any length (checked against the payload below)
            shape = tuple(d if want is None else want for d, want in zip(dims, shape, strict=True))
        if tuple(dims) != tuple(shape):
            self._fail(f"array {name!r} has shape {tuple(dims)}, expected {tuple(shape)}")
        dtype = np.dtype(DTYPES[code])
        if dtypes is not None and dtype.str not in dtypes and not flags & ZIGZAG:
            self._fail(f"array {name!r} has dtype {dtype}, expected one of {dtypes}")
        if flags & ZIGZAG and dtype.kind != "u":
            self._fail(f"array {name!r} is zigzag-coded but not unsigned")
        start = self._pos + 4 + 4 * ndim
        count = int(np.prod(shape, dtype=np.int64))
        end = start + count * dtype.itemsize
        if end > len(self._data):
            self._fail(f"array {name!r} needs {end - start} bytes, the payload has {len(self._data) - start}",
                       TruncatedError)
        raw = np.frombuffer(self._data[start:end], np.uint8)
        if flags & SHUFFLED:
            raw = raw.reshape(dtype.itemsize, count).T.copy()
        a = raw.view(dtype).reshape(shape)
        self._pos = end
        if flags & ZIGZAG:
            return unzigzag(a)
        return a.astype(dtype.newbyteorder("="))

    def ints(self, shape: tuple[int, ...], name: str) -> np.ndarray:
        a = self.array(shape, name)
        if a.dtype != np.int64:
            self._fail(f"array {name!r} must be zigzag-coded integers")
        return a

    def finish(self) -> None:
        if self._pos != len(self._data):
            self._fail(f"{len(self._data) - self._pos} unexpected bytes after the last array")
