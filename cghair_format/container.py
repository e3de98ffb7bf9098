"""The byte layer of a .cgh file: header, chunk table, checksums and zstd (spec: "File layout").

This module knows nothing of hair: it turns a list of :class:`Chunk` into bytes and back, checking
every size against the file length before allocating and every checksum before decoding.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import NamedTuple

import zstandard

from .errors import (
    BadMagicError,
    CghFormatError,
    ChecksumError,
    LimitError,
    TruncatedError,
    UnknownRequiredChunkError,
    UnsupportedVersionError,
)
from .parallel import map_threads

MAGIC = b"\x89CGH\r\n\x1a\n"
VERSION_MAJOR = 2
CHUNK_MINORS = {"PCNT": 1, "ANIM": 1}  # the minor version that added a chunk; a file states the lowest that
# describes it, so that a file without these is byte for byte what 2.0 wrote (spec 1.1)
# 1.x files hold the same chunks; only the arithmetic of quantized files' decoding changed (spec 4,
# "Arithmetic"), so a 1.x lossless file is read as before and a 1.x quantized one refused by the codec
READ_MAJORS = (1, 2)
HEADER = struct.Struct("<8sHHIQII")  # magic, major, minor, flags, file length, chunk count, crc
ENTRY = struct.Struct("<4sHBBQQQII")  # type, flags, codec, reserved, offset, stored, raw, crc, reserved
HEADER_SIZE = HEADER.size  # 32
ENTRY_SIZE = ENTRY.size  # 40
ALIGN = 8
CODEC_RAW, CODEC_ZSTD = 0, 1
FLAG_REQUIRED = 1

MAX_CHUNKS = 64
MAX_RAW_CHUNK = 1 << 31  # 2 GiB decompressed per chunk (implementation and format limit)
MAX_EXPANSION = 1 << 16  # no zstd stream expands more: a 128 KiB RLE block takes at least 4 bytes


@dataclass
class Chunk:
    type: str  # four ASCII characters
    payload: bytes  # uncompressed
    required: bool = True


def crc32(data: bytes | memoryview) -> int:
    return zlib.crc32(data) & 0xFFFFFFFF


class Stored(NamedTuple):
    """A chunk as it goes into the file: its codec and the bytes stored."""

    chunk: Chunk
    codec: int
    body: bytes


def compress(c: Chunk, level: int = 19) -> Stored:
    """A chunk zstd-compressed at ``level``, or raw where that is not smaller."""
    if len(c.type) != 4 or not c.type.isascii():
        raise ValueError(f"chunk type must be 4 ASCII characters, got {c.type!r}")
    if len(c.payload) > MAX_RAW_CHUNK:
        raise LimitError(f"chunk {c.type!r} of {len(c.payload)} bytes exceeds {MAX_RAW_CHUNK}")
    z = zstandard.ZstdCompressor(level=level, write_content_size=True).compress(c.payload)
    return Stored(c, CODEC_ZSTD, z) if len(z) < len(c.payload) else Stored(c, CODEC_RAW, c.payload)


def pack(chunks: list[Chunk], level: int = 19) -> bytes:
    """Serialise chunks: header, table, then each chunk (zstd when smaller) aligned to 8 bytes."""
    return assemble(map_threads(lambda c: compress(c, level), chunks))


def assemble(bodies: list[Stored]) -> bytes:
    """The file of chunks already compressed (:func:`compress`), in this order."""
    if len(bodies) > MAX_CHUNKS:
        raise LimitError(f"{len(bodies)} chunks exceed the limit of {MAX_CHUNKS}")
    offset = _align(HEADER_SIZE + ENTRY_SIZE * len(bodies))
    table, layout = b"", []
    for c, codec, stored in bodies:
        flags = FLAG_REQUIRED if c.required else 0
        table += ENTRY.pack(c.type.encode("ascii"), flags, codec, 0, offset, len(stored), len(c.payload),
                            crc32(stored), 0)
        layout.append((offset, stored))
        offset = _align(offset + len(stored))
    total = offset
    out = bytearray(total)
    minor = max((CHUNK_MINORS.get(c.type, 0) for c, _, _ in bodies), default=0)
    out[:HEADER_SIZE] = _header(VERSION_MAJOR, minor, 0, total, len(bodies), table)
    out[HEADER_SIZE:HEADER_SIZE + len(table)] = table
    for off, stored in layout:
        out[off:off + len(stored)] = stored
    return bytes(out)


def _header(major: int, minor: int, flags: int, length: int, count: int, table: bytes) -> bytes:
    """The 32 header bytes, checksum (over the header and the chunk table) included."""
    head = HEADER.pack(MAGIC, major, minor, flags, length, count, 0)[:-4]
    return head + struct.pack("<I", crc32(head + table))


def rewrite_header(data: bytes, **fields: int) -> bytes:
    """``data`` with header fields (``major``, ``minor``, ``flags``, ``length``, ``count``) replaced
    and the header checksum recomputed: how tests and the conformance vectors make the files of newer
    or faulty writers."""
    _, major, minor, flags, length, count, _ = HEADER.unpack_from(data)
    vals = dict(major=major, minor=minor, flags=flags, length=length, count=count) | fields
    table = bytes(data[HEADER_SIZE:HEADER_SIZE + ENTRY_SIZE * count])
    return _header(vals["major"], vals["minor"], vals["flags"], vals["length"], vals["count"], table) + \
        bytes(data[HEADER_SIZE:])


@dataclass
class ChunkInfo:
    type: str
    required: bool
    codec: int
    offset: int
    stored: int
    raw: int
    crc: int


def read_table(data: bytes | memoryview) -> tuple[tuple[int, int], list[ChunkInfo]]:
    """Parse and check the header and chunk table; returns ``(version, chunk infos)``."""
    data = memoryview(data)
    if len(data) < HEADER_SIZE:
        if bytes(data[:len(MAGIC)]) != MAGIC[:len(data)]:
            raise BadMagicError("not a .cgh file: wrong magic bytes", offset=0)
        raise TruncatedError(f"file of {len(data)} bytes is shorter than the {HEADER_SIZE}-byte header",
                             offset=len(data))
    magic, major, minor, _flags, length, count, head_crc = HEADER.unpack_from(data, 0)
    if magic != MAGIC:
        raise BadMagicError("not a .cgh file: wrong magic bytes", offset=0)
    if major not in READ_MAJORS:
        raise UnsupportedVersionError(f"format version {major}.{minor} is not supported by this reader "
                                      f"(major {VERSION_MAJOR}); upgrade cghair", offset=8)
    if count > MAX_CHUNKS:
        raise LimitError(f"chunk count {count} exceeds the limit of {MAX_CHUNKS}", offset=24)
    table_end = HEADER_SIZE + ENTRY_SIZE * count
    if length != len(data):
        kind = TruncatedError if length > len(data) else CghFormatError
        raise kind(f"header declares {length} bytes but the file has {len(data)}", offset=16)
    if table_end > len(data):
        raise TruncatedError(f"chunk table of {count} entries runs past the end of the file", offset=24)
    if crc32(bytes(data[:HEADER_SIZE - 4]) + bytes(data[HEADER_SIZE:table_end])) != head_crc:
        raise ChecksumError("header or chunk table checksum mismatch", offset=28)
    infos, seen, prev_end = [], set(), table_end
    for i in range(count):
        pos = HEADER_SIZE + ENTRY_SIZE * i
        ctype, flags, codec, _r, offset, stored, raw, crc, _r2 = ENTRY.unpack_from(data, pos)
        try:
            name = ctype.decode("ascii")
        except UnicodeDecodeError:
            raise CghFormatError(f"chunk {i} has a non-ASCII type {ctype!r}", offset=pos) from None
        if name in seen:
            raise CghFormatError(f"duplicate chunk {name!r}", offset=pos, chunk=name)
        seen.add(name)
        if codec not in (CODEC_RAW, CODEC_ZSTD):
            raise CghFormatError(f"unknown codec {codec}", offset=pos + 6, chunk=name)
        if offset < prev_end or offset % ALIGN or offset + stored > len(data):
            raise LimitError(f"chunk data [{offset}, {offset + stored}) is misplaced or outside the file "
                             f"of {len(data)} bytes", offset=pos + 8, chunk=name)
        if raw > MAX_RAW_CHUNK or (codec == CODEC_RAW and raw != stored) or \
                (codec == CODEC_ZSTD and raw > stored * MAX_EXPANSION):
            raise LimitError(f"declared size {raw} is impossible for {stored} stored bytes",
                             offset=pos + 24, chunk=name)
        _check_padding(data, prev_end, offset)
        prev_end = offset + stored
        infos.append(ChunkInfo(name, bool(flags & FLAG_REQUIRED), codec, offset, stored, raw, crc))
    _check_padding(data, prev_end, len(data))
    return (major, minor), infos


def _check_padding(data: memoryview, start: int, end: int) -> None:
    """Bytes between chunks (alignment padding) must be zero, so that every byte is checked."""
    if end - start >= ALIGN:
        raise CghFormatError(f"{end - start} unused bytes before the next chunk (at most {ALIGN - 1} allowed)",
                             offset=start)
    if any(data[start:end]):
        raise CghFormatError("alignment padding must be zero bytes", offset=start)


def verify(data: bytes | memoryview, known: set[str]) -> tuple[tuple[int, int], list[ChunkInfo]]:
    """:func:`read_table`, then every chunk's checksum, known or not (so that any changed byte of the
    file is found, also in an optional chunk this reader skips); fails on an unknown required chunk."""
    data = memoryview(data)
    version, infos = read_table(data)
    for i, info in enumerate(infos):
        pos = HEADER_SIZE + ENTRY_SIZE * i
        if info.type not in known and info.required:
            raise UnknownRequiredChunkError(f"required chunk type {info.type!r} is unknown to this reader; upgrade "
                                            "cghair", offset=pos, chunk=info.type)
        if crc32(data[info.offset:info.offset + info.stored]) != info.crc:
            raise ChecksumError("chunk checksum mismatch: the file is corrupt", offset=info.offset,
                                chunk=info.type)
    return version, infos


def payload(data: bytes | memoryview, info: ChunkInfo) -> bytes:
    """The uncompressed bytes of a chunk whose checksum :func:`verify` checked: exactly ``info.raw``
    bytes, never more in memory whatever the zstd frame's header declares (a streaming decompressor
    with a hard cap; python-zstandard's ``max_output_size`` is ignored where the frame states its size)."""
    stored = memoryview(data)[info.offset:info.offset + info.stored]
    if info.codec == CODEC_RAW:
        return bytes(stored)
    try:
        declared = zstandard.get_frame_parameters(stored).content_size
        if declared not in (info.raw, zstandard.CONTENTSIZE_UNKNOWN):
            raise CghFormatError(f"zstd frame declares {declared} bytes, the chunk table {info.raw}",
                                 offset=info.offset, chunk=info.type)
        reader = zstandard.ZstdDecompressor().stream_reader(stored, read_across_frames=True)
        raw = reader.read(info.raw + 1) if info.raw else b""
        extra = reader.read(1)  # the end of the input, or the error of a corrupt tail
    except zstandard.ZstdError as exc:
        raise CghFormatError(f"zstd stream is corrupt: {exc}", offset=info.offset, chunk=info.type) from None
    if len(raw) != info.raw or extra:
        raise CghFormatError(f"chunk decompresses to {len(raw) + len(extra)}{'+' if extra else ''} bytes, "
                             f"{info.raw} declared", offset=info.offset, chunk=info.type)
    return raw


def unpack(data: bytes | memoryview, known: set[str], wanted: set[str] | None = None
           ) -> tuple[tuple[int, int], list[ChunkInfo], dict[str, bytes]]:
    """Verify every chunk (:func:`verify`) and decompress the ``wanted`` ones (default: all ``known``);
    unknown optional chunks are skipped, an unknown required chunk fails."""
    version, infos = verify(data, known)
    wanted = known if wanted is None else wanted & known
    return version, infos, {i.type: payload(data, i) for i in infos if i.type in wanted}


def _align(n: int) -> int:
    return (n + ALIGN - 1) // ALIGN * ALIGN
