"""Helpers shared by the card-builder stages: progress bars, chunking, projection onto spines."""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager

import numpy as np

CHUNK_POINTS = 65536  # points per vectorised chunk: bounds the [n, M, 3] temporaries to ~50 MB


def progress(iterable: Iterable, desc: str, enabled: bool, total: int | None = None) -> Iterable:
    """``iterable`` wrapped in a tqdm bar on stderr when ``enabled`` and tqdm is installed."""
    if not enabled:
        return iterable
    try:
        from tqdm import tqdm
    except ImportError:
        return iterable
    return tqdm(iterable, desc=desc, total=total, leave=False)


def chunks(n: int, size: int = CHUNK_POINTS) -> list[tuple[int, int]]:
    return [(a, min(a + size, n)) for a in range(0, n, size)]


@contextmanager
def timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    """Add the wall time of the ``with`` body to ``timings[stage]``."""
    start = time.perf_counter()
    try:
        yield
    finally:
        timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-30)


def any_perpendicular(t: np.ndarray) -> np.ndarray:
    """A unit vector orthogonal to each unit vector of ``t [..., 3]``."""
    axis = np.zeros_like(t)
    smallest = np.argmin(np.abs(t), axis=-1)
    np.put_along_axis(axis, smallest[..., None], 1.0, axis=-1)
    return normalize(np.cross(t, axis))


def project_to_spines(spine: np.ndarray, card: np.ndarray, points: np.ndarray,
                      show_progress: bool = False) -> np.ndarray:
    """Spine parameter ``s`` in segment units of each point's nearest spine point.

    ``spine`` is ``[C, M+1, 3]``, ``card [N]`` the card of each point, ``points [N, 3]``. The result
    ``[N]`` lies in ``[0, M]``, except that points beyond the first or last spine point along the
    end segment's direction get ``s < 0`` or ``s > M`` (the strip extrapolates there).
    """
    m = spine.shape[1] - 1
    seg_a = spine[:, :-1].astype(np.float64)  # [C, M, 3]
    seg_d = (spine[:, 1:] - spine[:, :-1]).astype(np.float64)
    seg_len2 = np.maximum((seg_d ** 2).sum(-1), 1e-30)  # [C, M]
    out = np.empty(len(points), np.float64)
    size = max(1024, CHUNK_POINTS * 32 // max(m, 1))  # keep [n, M, 3] temporaries ~50 MB for any M
    for a, b in progress(chunks(len(points), size), "project", show_progress):
        c = card[a:b]
        p = points[a:b].astype(np.float64)[:, None, :]  # [n, 1, 3]
        rel = p - seg_a[c]  # [n, M, 3]
        t = np.einsum("nmc,nmc->nm", rel, seg_d[c]) / seg_len2[c]
        tc = np.clip(t, 0.0, 1.0)
        dist2 = ((rel - tc[..., None] * seg_d[c]) ** 2).sum(-1)
        k = np.argmin(dist2, axis=1)
        rows = np.arange(len(k))
        tk = tc[rows, k]
        traw = t[rows, k]
        tk = np.where((k == 0) & (traw < 0), traw, tk)
        tk = np.where((k == m - 1) & (traw > 1), traw, tk)
        out[a:b] = k + tk
    return out
