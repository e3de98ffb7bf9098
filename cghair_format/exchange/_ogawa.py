"""Alembic archives written directly: the Ogawa container and the Abc object/property layer.

No Alembic library installs from PyPI, so this writes the bytes itself (numpy and the standard
library only), following the layout of Alembic's AbcCoreOgawa, which every current Alembic reader
(Blender, Houdini, Maya, Unreal) reads. Only what a groom needs: objects, compound, scalar and array
properties of plain numeric types, with one sample on the default time sampling (index 0) or, for an
animated archive, one sample per frame on a uniform time sampling (index 1, :class:`TimeSampling`).

Ogawa (little-endian): a 16-byte header (``b"Ogawa"``, a "frozen" byte set to 0xff once the file
is complete, the format version 0x0001 big-endian, the uint64 position of the root group), then
*data* (uint64 size, bytes) and *groups* (uint64 child count, uint64 child positions). A child
position with the top bit set is data, otherwise a group; 0 is the empty group and the top bit
alone the empty data. Children are written before their group, so each group is written once.

Abc on Ogawa (AbcCoreOgawa version 0):

- root group: int32 AbcCoreOgawa version, int32 Alembic library version (XXYYZZ), the top
  object's group, the archive metadata string (``_ai_*`` keys), the time samplings, and the
  indexed metadata table.
- object group: its properties' compound group, one group per child object, then a data holding
  each child's header (uint32 name size, name, uint8 metadata index, and when that index is 255
  the uint32 size and text of the metadata) and 32 bytes of hashes (properties, children).
- compound property group: one group per property, then a data of property headers (a uint32
  ``info`` bit field: property type, size hint, POD type, extent, constant/homogeneous flags,
  metadata index; then sample count, name and metadata sized by the hint).
- array property group, per sample: a data (16-byte key, then the values) and the dimensions
  (empty data for rank-1 numeric arrays); scalar property: the data only. A property whose samples
  are all equal is *constant*: one sample stored, the header's sample count still the frames'.
  Otherwise every sample is stored (equal data shared) and the changes run from sample 1 to the
  last, which the header then need not state. A property on time sampling 1 says so after its
  sample count.
- time samplings, per sampling: uint32 the most samples any property has on it, float64 seconds
  per cycle, uint32 stored-time count (1: uniform) and float64 the first sample's time.
- metadata: ``key=value`` pairs joined by ``;``, keys sorted; short strings are stored once in
  the indexed table (index 1..254; 0 means empty, 255 written inline).

The 16-byte sample keys and the object hashes only let readers recognise equal samples and
objects; Alembic makes them with MurmurHash3 and SpookyHash, here they are MD5 digests of the
same content (readers never recompute them). Equal samples are stored once, as Alembic does.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..atomic import atomic_path

DATA_BIT = 1 << 63  # a child position with this bit set is data, otherwise a group
EMPTY_GROUP = 0
EMPTY_DATA = DATA_BIT
OGAWA_HEADER = b"Ogawa\x00\x00\x01"  # magic, frozen byte (0 while writing), version 0x0001
ABC_CORE_OGAWA_VERSION = 0
ALEMBIC_LIBRARY_VERSION = 10800  # the Alembic release (1.8.0) whose layout this follows
INLINE_METADATA = 255  # metadata index meaning "stored after the header"

# Alembic's PlainOldDataType numbers
POD = {np.dtype(np.bool_): 0, np.dtype(np.uint8): 1, np.dtype(np.int8): 2, np.dtype(np.uint16): 3,
       np.dtype(np.int16): 4, np.dtype(np.uint32): 5, np.dtype(np.int32): 6, np.dtype(np.uint64): 7,
       np.dtype(np.int64): 8, np.dtype(np.float16): 9, np.dtype(np.float32): 10, np.dtype(np.float64): 11}
SCALAR, ARRAY = 1, 2  # Alembic's PropertyType (compound is 0)


@dataclass(frozen=True)
class TimeSampling:
    """A uniform time sampling: ``frames`` samples, ``1 / fps`` seconds apart, the first at ``start``."""

    fps: float
    start: float
    frames: int


@dataclass
class Values:
    """A scalar (one value of ``extent`` numbers) or array property.
    ``values`` is ``[n]`` or ``[n, extent]`` (a scalar holds one such row): one sample on the default
    time sampling or, when ``sampled``, held at every frame of the archive's :class:`TimeSampling`;
    or a function of the frame giving that frame's sample (``sampled`` then)."""

    name: str
    values: np.ndarray | Callable[[int], np.ndarray]
    metadata: dict[str, str] = field(default_factory=dict)
    scalar: bool = False
    sampled: bool = False


@dataclass
class Compound:
    name: str
    properties: list[Values | Compound]
    metadata: dict[str, str] = field(default_factory=dict)


@dataclass
class Object:
    name: str
    metadata: dict[str, str]
    properties: list[Values | Compound]
    children: list[Object] = field(default_factory=list)


def serialize_metadata(md: dict[str, str]) -> bytes:
    for k, v in md.items():
        if not k or any(c in k + v for c in ";="):
            raise ValueError(f"Alembic metadata cannot hold ';' or '=' or an empty key: {k!r}={v!r}")
    return ";".join(f"{k}={v}" for k, v in sorted(md.items())).encode()


class OgawaWriter:
    """Appends data and groups to a file; ``close(root)`` points the header at the root group."""

    def __init__(self, f):
        self.f = f
        f.write(OGAWA_HEADER + bytes(8))
        self.pos = 16

    def data(self, *chunks) -> int:
        views = [memoryview(c).cast("B") for c in chunks]
        size = sum(v.nbytes for v in views)
        if size == 0:
            return EMPTY_DATA
        pos = self.pos
        self.f.write(struct.pack("<Q", size))
        for v in views:
            self.f.write(v)
        self.pos += 8 + size
        return pos | DATA_BIT

    def group(self, children: list[int]) -> int:
        if not children:
            return EMPTY_GROUP
        pos = self.pos
        self.f.write(struct.pack(f"<Q{len(children)}Q", len(children), *children))
        self.pos += 8 * (len(children) + 1)
        return pos

    def close(self, root: int) -> None:
        self.f.seek(8)
        self.f.write(struct.pack("<Q", root))
        self.f.seek(5)
        self.f.write(b"\xff")  # frozen: the archive is complete


def _uint(value: int, hint: int) -> bytes:
    return struct.pack(("<B", "<H", "<I")[hint], value)


def _size_hint(*sizes: int) -> int:
    m = max(sizes)
    return 0 if m < 256 else 1 if m < 65536 else 2


class _ArchiveWriter:
    def __init__(self, ogawa: OgawaWriter, sampling: TimeSampling | None = None):
        self.o = ogawa
        self.sampling = sampling
        self.max_samples = 1  # the most samples a property has on time sampling 1
        self.md_table: dict[bytes, int] = {}
        self.samples: dict[bytes, int] = {}  # key -> data position (equal samples stored once)

    def md_index(self, md: bytes) -> int:
        if not md:
            return 0
        if len(md) < 256:
            if md in self.md_table:
                return self.md_table[md] + 1
            if len(self.md_table) < 254:
                self.md_table[md] = len(self.md_table)
                return len(self.md_table)
        return INLINE_METADATA

    def sample(self, values: np.ndarray) -> tuple[int, bytes]:
        raw = np.ascontiguousarray(values).view(np.uint8).reshape(-1)
        if raw.nbytes == 0:
            return EMPTY_DATA, bytes(16)
        key = hashlib.md5(raw).digest()
        if key not in self.samples:
            self.samples[key] = self.o.data(key, raw)
        return self.samples[key], key

    def values(self, p: Values) -> tuple[int, bytes, bytes]:
        """Write one property's samples; return its group, header bytes and hash."""
        if p.sampled and self.sampling is None:
            raise ValueError(f"property {p.name}: sampled values need the archive's time sampling")
        if callable(p.values) and not p.sampled:
            raise ValueError(f"property {p.name}: values given per frame must be sampled")
        count = self.sampling.frames if p.sampled else 1
        sample = p.values if callable(p.values) else lambda f: p.values
        positions, keys, v = [], [], None
        for f in range(count if callable(p.values) else 1):
            v = self.checked(p, sample(f), v)
            pos, key = self.sample(v)
            positions.append(pos)
            keys.append(key)
        constant = len(set(keys)) == 1
        group = self.o.group([c for pos in positions[:1 if constant else None]
                              for c in ([pos] if p.scalar else [pos, EMPTY_DATA])])  # rank-1 dims: empty data
        extent = v.size if p.scalar else 1 if v.ndim == 1 else v.shape[1]
        md = serialize_metadata(p.metadata)
        index = self.md_index(md)
        name = p.name.encode()
        hint = _size_hint(len(md), len(name), count)
        info = (SCALAR if p.scalar else ARRAY) | ((1 if p.scalar else len(v)) == 1)  # bit 0: scalar-like
        info |= hint << 2 | POD[v.dtype.newbyteorder("=")] << 4 | 0x400 | extent << 12 | index << 20
        info |= 0x800 * constant | 0x100 * p.sampled  # constant; on time sampling 1
        head = struct.pack("<I", info) + _uint(count, hint) + (_uint(1, hint) if p.sampled else b"")
        head += _uint(len(name), hint) + name
        if index == INLINE_METADATA:
            head += _uint(len(md), hint) + md
        if p.sampled:
            self.max_samples = max(self.max_samples, 1 if constant else count)
        return group, head, hashlib.md5(head + b"".join(keys)).digest()

    @staticmethod
    def checked(p: Values, values, first: np.ndarray | None) -> np.ndarray:
        """``values`` as little-endian numbers of an Alembic type, shaped as frame 0's (``first``)."""
        v = np.asarray(values)
        if v.dtype not in POD:
            raise ValueError(f"property {p.name}: no Alembic type for {v.dtype}")
        v = v.astype(v.dtype.newbyteorder("<"), copy=False)
        if v.ndim > 2 or (p.scalar and v.ndim == 2 and len(v) != 1):
            raise ValueError(f"property {p.name}: values must be [n] or [n, extent] (one row for a scalar)")
        if first is not None and (v.dtype, v.shape) != (first.dtype, first.shape):
            raise ValueError(f"property {p.name}: a frame holds {v.dtype} {v.shape}, frame 0 {first.dtype} "
                             f"{first.shape}")
        return v

    def compound(self, props: list[Values | Compound]) -> tuple[int, bytes]:
        """Write the properties and their headers; return the group and the compound's hash."""
        children, heads, hashes = [], [], []
        for p in props:
            if isinstance(p, Compound):
                group, digest = self.compound(p.properties)
                md = serialize_metadata(p.metadata)
                index = self.md_index(md)
                name = p.name.encode()
                hint = _size_hint(len(md), len(name))
                head = struct.pack("<I", hint << 2 | index << 20) + _uint(len(name), hint) + name
                if index == INLINE_METADATA:
                    head += _uint(len(md), hint) + md
                digest = hashlib.md5(head + digest).digest()
            else:
                group, head, digest = self.values(p)
            children.append(group)
            heads.append(head)
            hashes.append(digest)
        if heads:
            children.append(self.o.data(b"".join(heads)))
        return self.o.group(children), hashlib.md5(b"".join(hashes)).digest()

    def object(self, props: list[Values | Compound], kids: list[Object]) -> tuple[int, bytes]:
        """Write an object's properties and children; return its group and its 32-byte hash."""
        prop_group, prop_hash = self.compound(props)
        children, heads, kid_hashes = [prop_group], [], []
        for kid in kids:
            group, digest = self.object(kid.properties, kid.children)
            children.append(group)
            kid_hashes.append(digest)
            md = serialize_metadata(kid.metadata)
            index = self.md_index(md)
            name = kid.name.encode()
            head = struct.pack("<I", len(name)) + name + struct.pack("<B", index)
            if index == INLINE_METADATA:
                head += struct.pack("<I", len(md)) + md
            heads.append(head)
        child_hash = hashlib.md5(b"".join(kid_hashes)).digest() if kids else bytes(16)
        children.append(self.o.data(b"".join(heads), prop_hash, child_hash))
        return self.o.group(children), prop_hash + child_hash

    def time_samplings(self) -> bytes:
        """The default sampling (index 0: uniform, 1 s per cycle, from time 0, one sample) and the
        archive's :class:`TimeSampling` (index 1) where it has one."""
        out = struct.pack("<IdId", 1, 1.0, 1, 0.0)
        if self.sampling is not None:
            out += struct.pack("<IdId", self.max_samples, 1.0 / self.sampling.fps, 1, self.sampling.start)
        return out

    def metadata_table(self) -> int:
        if not self.md_table:
            return EMPTY_DATA
        ordered = sorted(self.md_table, key=self.md_table.get)
        return self.o.data(b"".join(struct.pack("<B", len(m)) + m for m in ordered))


def write_archive(path: str | Path, children: list[Object], metadata: dict[str, str],
                  sampling: TimeSampling | None = None) -> None:
    """Write an Alembic (Ogawa) archive whose top object holds ``children``; ``metadata`` is the
    archive's (``_ai_Application``, ``_ai_DateWritten``, ...); ``sampling`` the time sampling of the
    ``sampled`` properties. Samples computed per frame are written as they come (memory: one frame)."""
    with atomic_path(path) as tmp:  # a failure or an interrupt leaves the old file, never a partial one
        _write(tmp, children, metadata, sampling)


def _write(path: Path, children: list[Object], metadata: dict[str, str], sampling: TimeSampling | None) -> None:
    with open(path, "wb") as f:
        o = OgawaWriter(f)
        w = _ArchiveWriter(o, sampling)
        top, _ = w.object([], children)
        archive_md = dict(metadata)
        archive_md.setdefault("_ai_AlembicVersion", "Alembic 1.8.0 layout (cghair writer)")
        root = o.group([o.data(struct.pack("<i", ABC_CORE_OGAWA_VERSION)),
                        o.data(struct.pack("<i", ALEMBIC_LIBRARY_VERSION)), top,
                        o.data(serialize_metadata(archive_md)), o.data(w.time_samplings()),
                        w.metadata_table()])
        o.close(root)
