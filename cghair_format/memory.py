"""Large output arrays, mapped and faulted in by the kernel ahead of the writes.

A fresh array of hundreds of MB costs more to fault in than to fill: decoding a large asset to
Gaussians writes its SH with one matrix product, which is quicker than faulting that memory in.
numpy's own allocation asks for transparent huge pages, which are quick once the process has freed
some, but the first such array of a process (and, now and then, a later one) stalls while the kernel
finds them. An anonymous mapping that the kernel populates ahead costs the same every time, and less
than faulting it in page by page (docs/compression.md, "Decode time, earlier runs").

On Linux 5.14 and later the kernel populates it a chunk at a time (``madvise(MADV_POPULATE_WRITE)``,
called through ctypes, which lets go of the GIL), so that other threads go on meanwhile:
:func:`.codec.read_with_gaussians` faults the SH in while its strands decode on another thread.
``mmap.madvise`` keeps the GIL (so does the ``mmap`` call itself in some Python versions), and one
populate of the whole mapping (``MAP_POPULATE``) holds the process's memory-map lock throughout, so
that a thread that maps memory meanwhile waits; either slows that decode down (docs/compression.md,
"Decode straight to Gaussians"). Older kernels get ``MAP_POPULATE``; other systems a
plain mapping.
"""

from __future__ import annotations

import ctypes
import mmap
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

try:  # numpy's switch for asking the kernel for huge pages for its arrays of 4 MB and more
    from numpy._core.multiarray import _set_madvise_hugepage
except ImportError:  # numpy 1.x
    try:
        from numpy.core.multiarray import _set_madvise_hugepage
    except ImportError:
        _set_madvise_hugepage = None

LARGE_BYTES = 64 << 20  # smaller arrays come from numpy as usual
POPULATE_CHUNK = 8 << 20
MADV_POPULATE_WRITE = 23  # linux/mman.h; Python's mmap module names it from 3.13 on


def empty(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised C-order array; from its own populated anonymous mapping when it has LARGE_BYTES
    or more (freed with the array, like any other)."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if size < LARGE_BYTES:
        return np.empty(shape, dtype)
    return np.frombuffer(_populated(size), dtype).reshape(shape)


def _libc_madvise():
    """libc's ``madvise``, which ctypes calls without the GIL; None where there is none to call."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, AttributeError):
        return None
    fn.argtypes, fn.restype = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int), ctypes.c_int
    return fn


_MADVISE = _libc_madvise()


def _populated(size: int) -> mmap.mmap:
    if not hasattr(mmap, "MAP_POPULATE"):
        return mmap.mmap(-1, size)
    flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
    m = mmap.mmap(-1, size, flags=flags)
    if _populate_by_chunks(m, size):
        return m
    m.close()  # a kernel before 5.14
    return mmap.mmap(-1, size, flags=flags | mmap.MAP_POPULATE)


def _populate_by_chunks(m: mmap.mmap, size: int) -> bool:
    """Fault ``m`` in, POPULATE_CHUNK bytes a call; False if the kernel cannot (nothing faulted then)."""
    if _MADVISE is None:
        return False
    address = np.frombuffer(m, np.uint8).ctypes.data  # the view goes with this call: m can close
    for start in range(0, size, POPULATE_CHUNK):
        if _MADVISE(address + start, min(POPULATE_CHUNK, size - start), MADV_POPULATE_WRITE) != 0:
            return start > 0  # short of memory midway: the rest faults in as it is written
    return True


_HUGE_PAGES_OFF = threading.Lock()
_huge_pages_users = 0
_huge_pages_were = True


@contextmanager
def without_huge_pages() -> Iterator[None]:
    """numpy's arrays in 4 KB pages while inside (in every thread; nested and concurrent uses are
    counted, and the last to leave restores numpy's setting).

    numpy asks the kernel for transparent huge pages for its arrays of 4 MB and more. Where the kernel
    compacts memory to find them (``defrag=madvise``, a common default), a process's first fresh GB
    stalls, so a process's first encode is quicker without them and only a later one, with the pages
    the first freed at hand, gains from them. The encoder does without, for the first encode (the
    command line's only one) and the slowest; a decode keeps them, as it is a little quicker with
    them (docs/compression.md, "Encode time" and "Decode straight to Gaussians")."""
    global _huge_pages_users, _huge_pages_were
    if _set_madvise_hugepage is None:
        yield
        return
    with _HUGE_PAGES_OFF:
        if _huge_pages_users == 0:
            _huge_pages_were = _set_madvise_hugepage(False)
        _huge_pages_users += 1
    try:
        yield
    finally:
        with _HUGE_PAGES_OFF:
            _huge_pages_users -= 1
            if _huge_pages_users == 0:
                _set_madvise_hugepage(_huge_pages_were)
