"""USC-HairSalon ``.data``: i32 strand count, then per strand i32 point count and that many f32 xyz.

The format has no header, units or up axis. Strands with zero points (HairSalon uses them for
empty scalp samples) are dropped.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ..strands import Strands
from ._common import StrandFileError, finish, need, offsets_from_counts, read_bytes

MAX_POINTS_PER_STRAND = 1 << 20


def load(path: str | Path) -> Strands:
    data = read_bytes(path)
    need(path, data, 4, "the strand count")
    n = int(np.frombuffer(data, "<i4", 1, 0)[0])
    if n <= 0 or 4 + 4 * n > len(data):
        raise StrandFileError(path, f"not a HairSalon .data file: strand count {n} does not fit the "
                                    f"{len(data)}-byte file")
    counts = np.empty(n, np.int64)
    starts = np.empty(n, np.int64)
    pos = 4
    for i in range(n):  # each count sits between variable-length blocks, so this walk is sequential
        need(path, data, pos + 4, f"the point count of strand {i}")
        c = int.from_bytes(data[pos:pos + 4], "little", signed=True)
        if c < 0 or c > MAX_POINTS_PER_STRAND:
            raise StrandFileError(path, f"strand {i} declares {c} points at byte offset {pos}")
        pos += 4
        need(path, data, pos + 12 * c, f"the {c} points of strand {i}")
        counts[i], starts[i] = c, pos
        pos += 12 * c
    if pos != len(data):
        raise StrandFileError(path, f"{len(data) - pos} unexpected bytes after the last strand "
                                    f"(byte offset {pos})")
    keep = counts > 0
    counts, starts = counts[keep], starts[keep]
    buf = np.frombuffer(data, np.uint8)
    off = offsets_from_counts(counts)
    point_starts = np.repeat(starts - off[:-1] * 12, counts) + np.arange(int(off[-1])) * 12
    raw = buf[(point_starts[:, None] + np.arange(12)[None, :])]
    points = raw.view("<f4").reshape(-1, 3).astype(np.float32)
    return finish(path, Strands(points, off))


def save(strands: Strands, path: str | Path) -> None:
    with atomic_open(path) as f:
        f.write(np.int32(strands.count).astype("<i4").tobytes())
        pts = strands.points.astype("<f4")
        for i in range(strands.count):
            a, b = int(strands.offsets[i]), int(strands.offsets[i + 1])
            f.write(np.int32(b - a).astype("<i4").tobytes())
            f.write(pts[a:b].tobytes())
