"""The simplest credible strand coder, the yardstick for the .cgh geometry chunks (:data:`GEOMETRY_CHUNKS`).

Grid quantization at the error bound, per-strand first- or second-order deltas, zigzag varints of
int32 and zstd level 19: whichever order codes smaller. Points are quantized on a cube grid of step
``2 bound / sqrt(3)``, so every point lies within ``bound`` of its input (Euclidean). ``cgh batch`` codes
every file with it beside the .cgh profiles, and ``make bench`` codes the real models with it.
"""

from __future__ import annotations

import numpy as np
import zstandard

ZSTD_LEVEL = 19
# the chunks of a .cgh that hold what the baseline codes: the strand points (cards, strands, children, counts)
GEOMETRY_CHUNKS = ("CARD", "STRD", "CHLD", "PCNT")


def quantize(points: np.ndarray, bound: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(integer grid coordinates [N, 3] int64, grid origin [3], step) within ``bound`` of ``points``."""
    step = 2.0 * bound / np.sqrt(3.0)
    origin = points.min(0).astype(np.float64)
    return np.rint((points - origin) / step).astype(np.int64), origin, step


def _deltas(q: np.ndarray, offsets: np.ndarray, order: int) -> np.ndarray:
    """``order`` passes of a within-strand difference; pass k keeps a strand's first k values."""
    within = np.arange(len(q)) - np.repeat(offsets[:-1], np.diff(offsets))
    d = q.copy()
    for k in range(1, order + 1):
        prev = np.concatenate([np.zeros((1, 3), np.int64), d[:-1]])
        d = np.where((within < k)[:, None], d, d - prev)
    return d


def encode(points: np.ndarray, offsets: np.ndarray, bound: float) -> tuple[int, np.ndarray]:
    """(bytes of the smaller of the first- and second-order codes, the decoded points [N, 3])."""
    q, origin, step = quantize(np.asarray(points, np.float64), bound)
    counts = np.diff(offsets).astype(np.uint32)
    best = None
    for order in (1, 2):
        d = _deltas(q, offsets, order)
        zig = ((d << 1) ^ (d >> 63)).astype(np.uint32)  # small magnitudes -> small unsigned values
        planes = np.ascontiguousarray(zig.T)  # x, y, z streams apart: each has its own statistics
        payload = counts.tobytes() + planes.tobytes()
        size = len(zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress(payload)) + 8 * 3 + 8 + 1
        best = size if best is None else min(best, size)
    return best, (q * step + origin).astype(np.float32)
