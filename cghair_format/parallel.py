"""Row-block parallelism for numpy work: numpy releases the GIL inside its array loops, so threads
over independent blocks of strands use every core, and small blocks stay in cache."""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

A = TypeVar("A")
T = TypeVar("T")
BLOCK_ROWS = 2048


def map_threads(fn: Callable[[A], T], items: list[A]) -> list[T]:
    """``[fn(item) for item in items]``, in order, run on up to one thread per core (for work that
    releases the GIL: numpy array loops, zstd)."""
    if len(items) <= 1:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(max_workers=min(len(items), os.cpu_count() or 1)) as pool:
        return list(pool.map(fn, items))


def map_blocks(fn: Callable[[slice], T], rows: int, block: int = BLOCK_ROWS) -> list[T]:
    """``[fn(slice) for each block of rows]``, in order, run on up to one thread per core."""
    return map_threads(fn, [slice(a, min(a + block, rows)) for a in range(0, rows, block)])
