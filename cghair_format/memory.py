"""Large output arrays, mapped and faulted in by the kernel in one go.

A fresh array of hundreds of MB costs more to fault in than to fill: decoding the paper-scale asset
to Gaussians writes 475 MB of SH, a matrix product of about 0.1 s. numpy's own allocation asks for
transparent huge pages, which are quick once the process has freed some, but the first such array
of a process (and, now and then, a later one) stalls while the kernel finds them: 1.05 s, then
0.05-0.22 s, for 475 MB on this project's 2-core machine (COMPRESSION.md, "Decode time, earlier
runs"). An anonymous mapping that the kernel populates at once (``MAP_POPULATE``, Linux) takes
0.13-0.20 s every time, page by page faulting 0.27-0.33 s.
"""

from __future__ import annotations

import mmap

import numpy as np

LARGE_BYTES = 64 << 20  # smaller arrays come from numpy as usual
_FLAGS = {"flags": mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | getattr(mmap, "MAP_POPULATE", 0)} \
    if hasattr(mmap, "MAP_ANONYMOUS") else {}


def empty(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised C-order array; from its own populated anonymous mapping when it has LARGE_BYTES
    or more (freed with the array, like any other)."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if size < LARGE_BYTES:
        return np.empty(shape, dtype)
    return np.frombuffer(mmap.mmap(-1, size, **_FLAGS), dtype).reshape(shape)
