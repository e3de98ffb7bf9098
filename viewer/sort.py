"""Sorting splats by depth: a GPU radix sort in compute shaders, and a numpy fallback.

Both sort ``count`` 32-bit keys with their 32-bit values in place, stably (equal keys keep
their input order, as the reference splatter's stable argsort does). The GPU sort makes eight
passes of 4 bits; each pass is a per-block digit histogram, one prefix scan over all blocks,
and a stable scatter (see the ``radix_*.comp.glsl`` shaders).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .pipeline import Programs, bind, set_uniforms
from .shader_constants import RADIX_BITS, RADIX_ITEMS, RADIX_THREADS

DIGITS = 1 << RADIX_BITS
BLOCK = RADIX_THREADS * RADIX_ITEMS  # keys per work group
SORT_MODES = ("gpu", "cpu")


class GpuRadixSort:
    """Stable LSD radix sort of (uint32 key, uint32 value) storage buffers on the GPU."""

    def __init__(self, ctx: Any, programs: Programs, capacity: int):
        self.ctx = ctx
        self.capacity = int(capacity)
        self.blocks = max(1, math.ceil(self.capacity / BLOCK))
        self.keys_tmp = ctx.buffer(reserve=max(16, 4 * self.capacity))
        self.values_tmp = ctx.buffer(reserve=max(16, 4 * self.capacity))
        self.block_hist = ctx.buffer(reserve=DIGITS * self.blocks * 4)
        self.hist = programs.compute("radix_hist")
        self.scan = programs.compute("radix_scan")
        self.scatter = programs.compute("radix_scatter")

    def sort(self, keys: Any, values: Any, count: int, key_bits: int = 32) -> None:
        """Sort ``keys`` and ``values`` (buffers of at least ``count`` uints) by key, in place."""
        if count > self.capacity:
            raise ValueError(f"sort of {count} keys exceeds this sorter's capacity {self.capacity}")
        blocks = max(1, math.ceil(count / BLOCK))
        passes = math.ceil(key_bits / RADIX_BITS)
        passes += passes % 2  # an even number of passes leaves the result in the input buffers
        src, dst = (keys, values), (self.keys_tmp, self.values_tmp)
        for p in range(passes):
            shift = p * RADIX_BITS
            bind(self.hist, Keys=src[0], BlockHist=self.block_hist)
            set_uniforms(self.hist, u_count=count, u_shift=shift, u_blocks=blocks)
            self.hist.run(blocks, 1, 1)
            self.ctx.memory_barrier()
            bind(self.scan, BlockHist=self.block_hist)
            set_uniforms(self.scan, u_count=DIGITS * blocks)
            self.scan.run(1, 1, 1)
            self.ctx.memory_barrier()
            bind(self.scatter, KeysIn=src[0], ValuesIn=src[1], KeysOut=dst[0], ValuesOut=dst[1],
                 BlockHist=self.block_hist)
            set_uniforms(self.scatter, u_count=count, u_shift=shift, u_blocks=blocks)
            self.scatter.run(blocks, 1, 1)
            self.ctx.memory_barrier()
            src, dst = dst, src

    def release(self) -> None:
        for buf in (self.keys_tmp, self.values_tmp, self.block_hist):
            buf.release()


def cpu_sort(keys: Any, values: Any, count: int, key_bits: int = 32) -> None:
    """The fallback: read the keys back, sort them stably with numpy, upload keys and values.
    Keys below ``2 ** key_bits``; up to 16 bits take one radix pass."""
    k = np.frombuffer(keys.read(size=4 * count), np.uint32)
    v = np.frombuffer(values.read(size=4 * count), np.uint32)
    order = sort_order(k, key_bits)
    keys.write(k[order].tobytes())
    values.write(v[order].tobytes())


def sort_order(keys: np.ndarray, key_bits: int = 32) -> np.ndarray:
    """The stable sorting permutation of uint32 ``keys`` below ``2 ** key_bits``."""
    return np.argsort(keys.astype(np.uint16), kind="stable") if key_bits <= 16 else stable_order(keys)


def stable_order(keys: np.ndarray) -> np.ndarray:
    """``numpy.argsort(keys, kind="stable")`` for uint32 keys, as two 16-bit radix passes (numpy
    sorts 16-bit keys by radix: faster than one 32-bit stable argsort; docs/viewer.md)."""
    keys = np.asarray(keys, np.uint32)
    low = np.argsort((keys & 0xFFFF).astype(np.uint16), kind="stable")
    return low[np.argsort((keys[low] >> 16).astype(np.uint16), kind="stable")]
