"""The compute rasterizer: tile binning and per-tile front-to-back blending in compute shaders.

After the preprocess and the depth sort (:class:`viewer.renderer.Renderer`), every visible splat
is duplicated into the 16 x 16 tiles its oriented footprint touches (``tile_count``, a scan of the
totals of runs of 16 splats, ``tile_emit``: entries in depth order), the entries are sorted by tile with the
stable GPU radix sort (so each tile's entries stay in depth order), and each tile's range is
found (``tile_ranges``, which also copies the entries into an image); where the renderer sorts on
the CPU, numpy sorts the entries, counts each tile's and writes the entry image itself.
``tile_blend`` then runs one work group per tile, blending the tile's splats front to back and stopping each pixel at
T < 1e-4: the cost follows the visible splats, not all the splats over a pixel as fixed-function
blending does. The blend reads splats as texels (the preprocess writes a record image next to its
buffers): llvmpipe fetches texels as vectors but loads storage and shared memory one invocation
at a time. Same image contract as the raster path and the reference splatter.

The entry buffers grow on demand up to :attr:`TileBinner.capacity` entries (one storage block);
a view that needs more (very close views of dense hair) is reported by :meth:`TileBinner.bin`
returning ``False``, and the renderer draws that frame with the raster path.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .pipeline import TEXELS_PER_ROW, Programs, bind, data_image, dispatch, max_texture_size, set_uniforms
from .sort import GpuRadixSort, sort_order

TILE = 16  # pixels per tile side (tile_common.glsl)
RECORD_TEXELS = 4  # texels per splat record (preprocess.comp.glsl)
RUN = 16  # consecutive sorted splats per binning invocation (tile_common.glsl ITEMS)
MIN_ENTRIES = 1 << 20  # first allocation of the entry buffers
GROWTH = 1.25  # head room when the entry buffers grow


def max_splats(ctx: Any) -> int:
    """Most splats the record image of this context holds (GL_MAX_TEXTURE_SIZE rows)."""
    return TEXELS_PER_ROW * max_texture_size(ctx) // RECORD_TEXELS


def tile_grid(width: int, height: int) -> tuple[int, int]:
    return math.ceil(width / TILE), math.ceil(height / TILE)


class TileBinner:
    """Buffers and passes of the compute rasterizer for one renderer."""

    def __init__(self, ctx: Any, programs: Programs, splats: int, capacity: int, sort_mode: str = "gpu"):
        self.ctx = ctx
        self.programs = programs
        self.sort_mode = sort_mode  # of the tile entries: the renderer's ("cpu" on llvmpipe, measured faster)
        self.capacity = min(int(capacity), TEXELS_PER_ROW * max_texture_size(ctx))  # most entries one frame may need
        n = max(splats, 1)
        self.splats = n
        self._records = None
        self.counts = ctx.buffer(reserve=4 * n)
        self.run_sums = ctx.buffer(reserve=4 * max(1, math.ceil(n / RUN)))
        self.total = ctx.buffer(reserve=4)
        self.entries = 0  # entries of the last bin()
        self.entries_needed = 0  # entries the last bin() needed (more than entries if over capacity)
        self.allocated = 0
        self.keys = self.values = self.sorter = self.entry_image = None
        self.ranges = None
        self.tiles = (0, 0)

    @property
    def records(self) -> Any:
        """The splat record image the preprocess writes (allocated on first use: 64 bytes a splat)."""
        if self._records is None:
            self._records = data_image(self.ctx, RECORD_TEXELS * self.splats, 4, "f4")
        return self._records

    def _reserve(self, entries: int) -> None:
        if entries <= self.allocated and self.keys is not None:
            return
        size = min(self.capacity, max(MIN_ENTRIES, int(entries * GROWTH)))
        for obj in (self.keys, self.values, self.entry_image):
            if obj is not None:
                obj.release()
        if self.sorter is not None:
            self.sorter.release()
        self.keys = self.ctx.buffer(reserve=4 * size)
        self.values = self.ctx.buffer(reserve=4 * size)
        self.entry_image = data_image(self.ctx, size, 1, "u4")
        self.sorter = GpuRadixSort(self.ctx, self.programs, size) if self.sort_mode == "gpu" else None
        self.allocated = size

    def _ranges(self, width: int, height: int) -> None:
        tiles = tile_grid(width, height)
        if tiles != self.tiles:
            if self.ranges is not None:
                self.ranges.release()
            self.ranges = self.ctx.buffer(reserve=8 * tiles[0] * tiles[1])
            self.tiles = tiles

    def bin(self, order: Any, visible: int, width: int, height: int) -> bool:
        """Tile entries of the first ``visible`` splats of ``order`` (their records written by the
        preprocess); ``False`` if over capacity."""
        self._ranges(width, height)
        tiles_x, tiles_y = self.tiles
        self.total.clear()
        self.entries = self.entries_needed = 0
        runs = math.ceil(visible / RUN)
        if visible == 0:
            self._reserve(0)
            self.ranges.clear()
            return True
        viewport = (float(width), float(height))
        prog = self.programs.compute("tile_count")
        bind(order, self.counts, self.run_sums, self.total)
        self.records.use(0)
        set_uniforms(prog, u_count=visible, u_viewport=viewport, u_tiles_x=tiles_x, u_records=0)
        dispatch(self.ctx, prog, runs)
        scan = self.programs.compute("radix_scan")  # exclusive scan in place, one work group
        bind(self.run_sums)
        set_uniforms(scan, u_count=runs)
        scan.run(1, 1, 1)
        self.ctx.memory_barrier()
        entries = self.entries_needed = int(np.frombuffer(self.total.read(), np.uint32)[0])
        if entries > self.capacity:
            return False
        self._reserve(entries)
        self.entries = entries
        prog = self.programs.compute("tile_emit")
        bind(order, self.counts, self.run_sums, self.keys, self.values)
        self.records.use(0)
        set_uniforms(prog, u_count=visible, u_viewport=viewport, u_tiles_x=tiles_x, u_records=0)
        dispatch(self.ctx, prog, runs)
        key_bits = max(1, (tiles_x * tiles_y - 1).bit_length())
        if self.sorter is None:
            self._sort_on_cpu(entries, key_bits)
            return True
        self.sorter.sort(self.keys, self.values, entries, key_bits=key_bits)
        self.ranges.clear()
        prog = self.programs.compute("tile_ranges")
        bind(self.keys, self.ranges, self.values)
        self.entry_image.bind_to_image(2, read=False, write=True)
        set_uniforms(prog, u_count=entries)
        dispatch(self.ctx, prog, entries)
        return True

    def _sort_on_cpu(self, entries: int, key_bits: int) -> None:
        """Sort the entries by tile with numpy, which also gives the tiles' ranges (a count per
        tile), and write the sorted slots straight into the entry image: no ranges pass."""
        tiles = np.frombuffer(self.keys.read(size=4 * entries), np.uint32)
        slots = np.frombuffer(self.values.read(size=4 * entries), np.uint32)
        ends = np.cumsum(np.bincount(tiles, minlength=self.tiles[0] * self.tiles[1]), dtype=np.uint32)
        starts = np.concatenate([np.zeros(1, np.uint32), ends[:-1]])
        self.ranges.write(np.stack([starts, ends], axis=1).tobytes())
        rows = -(-entries // TEXELS_PER_ROW)
        image = np.zeros(rows * TEXELS_PER_ROW, np.uint32)
        image[:entries] = slots[sort_order(tiles, key_bits)]
        self.entry_image.write(image.tobytes(), viewport=(0, 0, TEXELS_PER_ROW, rows))

    def blend(self, image: Any, width: int, height: int) -> None:
        """Blend every tile into ``image`` (an RGBA32F texture of ``width`` x ``height``)."""
        tiles_x, tiles_y = self.tiles
        prog = self.programs.compute("tile_blend")
        bind(None, self.ranges)
        image.bind_to_image(0, read=False, write=True)
        self.entry_image.use(0)
        self.records.use(1)
        set_uniforms(prog, u_size=(width, height), u_tiles_x=tiles_x, u_entries=0, u_records=1)
        prog.run(tiles_x, tiles_y, 1)
        self.ctx.memory_barrier()

    def release(self) -> None:
        for obj in (self.counts, self.run_sums, self.total, self.keys, self.values, self.ranges, self._records,
                    self.entry_image):
            if obj is not None:
                obj.release()
        if self.sorter is not None:
            self.sorter.release()
