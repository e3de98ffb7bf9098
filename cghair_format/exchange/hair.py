"""Cem Yuksel's HAIR format (``.hair``): a 128-byte header, then optional per-strand and per-point arrays.

Header: ``"HAIR"``, u32 strand count, u32 point count, u32 array bits (1 segments, 2 points,
4 thickness, 8 transparency, 16 colours), u32 default segments, f32 default thickness,
f32 default transparency, f32x3 default colour, 88 bytes of text. Arrays follow in bit order:
u16 segments per strand, f32x3 points, f32 thickness, f32 transparency, f32x3 colours.
The format names no units or up axis. The header's default thickness and colour are not
applied when their arrays are absent: writers fill them with placeholders (Bangs_100.hair
says white and 1.0), so only stored per-point arrays become colours and widths (checked as
:func:`._common.finish` says; colours above 1 are clipped).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ..strands import Strands
from ._common import StrandFileError, finish, need, offsets_from_counts, read_bytes

MAGIC = b"HAIR"
HEADER = struct.Struct("<4sIIIIff3f88s")  # 128 bytes
BIT_SEGMENTS, BIT_POINTS, BIT_THICKNESS, BIT_TRANSPARENCY, BIT_COLORS = 1, 2, 4, 8, 16


def load(path: str | Path) -> Strands:
    data = read_bytes(path)
    need(path, data, HEADER.size, "the 128-byte header")
    magic, n_strands, n_points, bits, d_seg, *_ = HEADER.unpack_from(data)
    if magic != MAGIC:
        raise StrandFileError(path, f"not a Cem Yuksel .hair file: magic is {magic!r}, expected b'HAIR'")
    if not bits & BIT_POINTS:
        raise StrandFileError(path, "the header says the file has no points array")
    pos = HEADER.size
    if n_strands > n_points or n_points > len(data) // 12:  # every strand has a point of 12 bytes at least
        raise StrandFileError(path, f"header declares {n_points} points in {n_strands} strands, which a "
                                    f"{len(data)}-byte file cannot hold")
    if bits & BIT_SEGMENTS:
        need(path, data, pos + 2 * n_strands, f"the segments array of {n_strands} strands")
        segments = np.frombuffer(data, "<u2", n_strands, pos).astype(np.int64)
        pos += 2 * n_strands
    else:
        segments = np.full(n_strands, d_seg, np.int64)
    counts = segments + 1
    if int(counts.sum()) != n_points:
        raise StrandFileError(path, f"segment counts add up to {int(counts.sum())} points, "
                                    f"the header declares {n_points}")
    need(path, data, pos + 12 * n_points, f"the points array of {n_points} points")
    points = np.frombuffer(data, "<f4", 3 * n_points, pos).reshape(-1, 3).astype(np.float32)
    pos += 12 * n_points
    widths = None
    if bits & BIT_THICKNESS:
        need(path, data, pos + 4 * n_points, "the thickness array")
        widths = np.frombuffer(data, "<f4", n_points, pos).astype(np.float32)
        pos += 4 * n_points
    if bits & BIT_TRANSPARENCY:
        need(path, data, pos + 4 * n_points, "the transparency array")
        pos += 4 * n_points
    colors = None
    if bits & BIT_COLORS:
        need(path, data, pos + 12 * n_points, "the colours array")
        colors = np.frombuffer(data, "<f4", 3 * n_points, pos).reshape(-1, 3).astype(np.float32)
    return finish(path, Strands(points, offsets_from_counts(counts), colors, widths),
                  {"widths": "the thickness array", "colors": "the colours array"})


def save(strands: Strands, path: str | Path) -> None:
    counts = strands.point_counts
    if (counts < 1).any() or (counts > 65536).any():
        raise StrandFileError(path, ".hair stores 0..65535 segments per strand; got strands with "
                                    f"{int(counts.min())}..{int(counts.max())} points")
    bits = BIT_SEGMENTS | BIT_POINTS
    if strands.widths is not None:
        bits |= BIT_THICKNESS
    if strands.colors is not None:
        bits |= BIT_COLORS
    info = b"Written by cghair (CGHair strand exchange)".ljust(88, b"\0")
    header = HEADER.pack(MAGIC, strands.count, len(strands.points), bits, 0, 1.0, 0.0, 1.0, 1.0, 1.0, info)
    with atomic_open(path) as f:
        f.write(header)
        f.write((counts - 1).astype("<u2").tobytes())
        f.write(strands.points.astype("<f4").tobytes())
        if strands.widths is not None:
            f.write(strands.widths.astype("<f4").tobytes())
        if strands.colors is not None:
            f.write(strands.colors.astype("<f4").tobytes())
