"""Large output arrays in memory of the system's default page size.

numpy advises the kernel to back every large array with transparent huge pages (``madvise``). Where
the kernel then defragments on demand for such requests (``/sys/kernel/mm/transparent_hugepage/defrag``
= ``madvise``, a common default), a fresh array of hundreds of MB can stall for half a second while it
compacts memory. Decoding the paper-scale asset to Gaussians allocates 475 MB of SH at once: 8 decodes
took 0.66-1.71 s with numpy's arrays and 0.70-1.01 s with these (README, "Decode time").
"""

from __future__ import annotations

import mmap

import numpy as np

LARGE_BYTES = 64 << 20  # smaller arrays come from numpy as usual


def empty(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised C-order array; from its own anonymous mapping when it has LARGE_BYTES or more
    (freed with the array, like any other)."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if size < LARGE_BYTES:
        return np.empty(shape, dtype)
    return np.frombuffer(mmap.mmap(-1, size), dtype).reshape(shape)
