"""The compute rasterizer: tile binning and per-tile front-to-back blending in compute shaders.

After the preprocess and the depth sort (:meth:`viewer.renderer.Renderer.frame`), every visible splat
is duplicated into the TILE x TILE (16 x 16) tiles its oriented footprint touches (``tile_count``, a scan of the
totals of runs of 16 splats, ``tile_emit``: entries in depth order), the entries are sorted by tile with the
stable GPU radix sort (so each tile's entries stay in depth order), and each tile's range is
found (``tile_ranges``, which also copies the entries into an image); where the renderer sorts on
the CPU, numpy sorts the entries, counts each tile's and writes the entry image itself.
``tile_blend`` then runs one work group per tile, blending the tile's splats front to back and stopping each pixel at
T < 1e-4: the cost follows the visible splats, not all the splats over a pixel as fixed-function
blending does. A tile with more than ``BLEND_CHUNK`` entries is blended over several dispatches
(llvmpipe ends a shader invocation after 65,535 loop iterations; docs/viewer.md). The blend
reads splats as texels (the preprocess writes a record image next to its buffers): llvmpipe
fetches texels as vectors but loads storage and shared memory one invocation at a time. Same
image contract as the raster path and the reference splatter.

The entry buffers grow on demand up to :attr:`TileRasterizer.capacity` entries (one storage block);
a view that needs more (very close views of dense hair) is reported by :meth:`TileRasterizer.gather`
returning ``False``, and the renderer draws that frame with the raster path.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .pipeline import Programs, bind, bind_images, data_image, dispatch, max_texture_size, set_uniforms, use_textures
from .rasterizer import Target
from .shader_constants import BLEND_CHUNK, EMIT_CHUNK, RECORD_VEC4S, RUN, TEXELS_PER_ROW, TILE
from .sort import GpuRadixSort, sort_order

MIN_ENTRIES = 1 << 20  # first allocation of the entry buffers
GROWTH = 1.25  # head room when the entry buffers grow


def max_splats(ctx: Any) -> int:
    """Most splats the record image of this context holds (GL_MAX_TEXTURE_SIZE rows)."""
    return TEXELS_PER_ROW * max_texture_size(ctx) // RECORD_VEC4S


def tile_grid(width: int, height: int) -> tuple[int, int]:
    return math.ceil(width / TILE), math.ceil(height / TILE)


class TileRasterizer:
    """The compute rasterizer of one renderer (a :class:`viewer.rasterizer.Rasterizer`): its
    buffers, the binning passes and the blend."""

    name = "compute"

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
        self.total = ctx.buffer(reserve=8)  # entries, and the most of one run
        self.entries = 0  # entries of the last gather()
        self.entries_needed = 0  # entries the last gather() needed (more than entries if over capacity)
        self.longest = 0  # most entries of one tile in the last gather() (the blend's dispatches)
        self.allocated = 0
        self.keys = self.values = self.sorter = self.entry_image = None
        self.ranges = None
        self.tiles = (0, 0)

    @property
    def records(self) -> Any:
        """The splat record image the preprocess writes (allocated on first use: 64 bytes a splat)."""
        if self._records is None:
            self._records = data_image(self.ctx, RECORD_VEC4S * self.splats, 4, "f4")
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

    def preprocess_outputs(self, program: Any) -> None:
        """The preprocess writes the record image (and not the raster path's buffers)."""
        bind_images(program, u_records=self.records)
        set_uniforms(program, u_write_records=True, u_write_buffers=False)

    def gather(self, order: Any, visible: int, width: int, height: int) -> bool:
        """Tile entries of the first ``visible`` splats of ``order`` (their records written by the
        preprocess); ``False`` if over capacity."""
        self._ranges(width, height)
        tiles_x, tiles_y = self.tiles
        self.total.clear()
        self.entries = self.entries_needed = self.longest = 0
        runs = math.ceil(visible / RUN)
        if visible == 0:
            self._reserve(0)
            self.ranges.clear()
            return True
        viewport = (float(width), float(height))
        prog = self.programs.compute("tile_count")
        bind(prog, Order=order, Counts=self.counts, RunSums=self.run_sums, Total=self.total)
        use_textures(prog, u_records=self.records)
        set_uniforms(prog, u_count=visible, u_viewport=viewport, u_tiles_x=tiles_x)
        dispatch(self.ctx, prog, runs)
        scan = self.programs.compute("radix_scan")  # exclusive scan in place, one work group
        bind(scan, BlockHist=self.run_sums)
        set_uniforms(scan, u_count=runs)
        scan.run(1, 1, 1)
        self.ctx.memory_barrier()
        entries, longest_run = (int(v) for v in np.frombuffer(self.total.read(), np.uint32))
        self.entries_needed = entries
        if entries > self.capacity:
            return False
        self._reserve(entries)
        self.entries = entries
        prog = self.programs.compute("tile_emit")
        bind(prog, Order=order, Counts=self.counts, RunOffsets=self.run_sums, TileKeys=self.keys,
             TileValues=self.values)
        use_textures(prog, u_records=self.records)
        set_uniforms(prog, u_count=visible, u_viewport=viewport, u_tiles_x=tiles_x)
        for skip in range(0, longest_run, EMIT_CHUNK):  # llvmpipe's loop limit (tile_emit.comp.glsl)
            set_uniforms(prog, u_skip=skip)
            dispatch(self.ctx, prog, runs)
        key_bits = max(1, (tiles_x * tiles_y - 1).bit_length())
        if self.sorter is None:
            self._sort_on_cpu(entries, key_bits)
            return True
        self.sorter.sort(self.keys, self.values, entries, key_bits=key_bits)
        self.ranges.clear()
        prog = self.programs.compute("tile_ranges")
        bind(prog, TileKeys=self.keys, Ranges=self.ranges, TileValues=self.values)
        bind_images(prog, u_entries=self.entry_image)
        set_uniforms(prog, u_count=entries)
        dispatch(self.ctx, prog, entries)
        self.longest = entries if entries <= BLEND_CHUNK else self._longest_range()
        return True

    def _longest_range(self) -> int:
        """Most entries of one tile, from the ranges the GPU found."""
        ranges = np.frombuffer(self.ranges.read(), np.uint32).reshape(-1, 2)
        return int((ranges[:, 1] - ranges[:, 0]).max())

    def _sort_on_cpu(self, entries: int, key_bits: int) -> None:
        """Sort the entries by tile with numpy, which also gives the tiles' ranges (a count per
        tile), and write the sorted slots straight into the entry image: no ranges pass."""
        tiles = np.frombuffer(self.keys.read(size=4 * entries), np.uint32)
        slots = np.frombuffer(self.values.read(size=4 * entries), np.uint32)
        counts = np.bincount(tiles, minlength=self.tiles[0] * self.tiles[1])
        self.longest = int(counts.max())
        ends = np.cumsum(counts, dtype=np.uint32)
        starts = np.concatenate([np.zeros(1, np.uint32), ends[:-1]])
        self.ranges.write(np.stack([starts, ends], axis=1).tobytes())
        rows = -(-entries // TEXELS_PER_ROW)
        image = np.zeros(rows * TEXELS_PER_ROW, np.uint32)
        image[:entries] = slots[sort_order(tiles, key_bits)]
        self.entry_image.write(image.tobytes(), viewport=(0, 0, TEXELS_PER_ROW, rows))

    def draw(self, target: Target, width: int, height: int) -> None:
        """Blend every tile into the target's RGBA32F texture (``width`` x ``height``, overwritten):
        one dispatch per ``BLEND_CHUNK`` entries of the longest tile, each resuming from the image."""
        tiles_x, tiles_y = self.tiles
        prog = self.programs.compute("tile_blend")
        bind(prog, Ranges=self.ranges)
        bind_images(prog, read=True, u_image=target.texture)
        use_textures(prog, u_entries=self.entry_image, u_records=self.records)
        set_uniforms(prog, u_size=(width, height), u_tiles_x=tiles_x)
        for skip in range(0, max(self.longest, 1), BLEND_CHUNK):
            set_uniforms(prog, u_skip=skip)
            prog.run(tiles_x, tiles_y, 1)
            self.ctx.memory_barrier()

    def release(self) -> None:
        for obj in (self.counts, self.run_sums, self.total, self.keys, self.values, self.ranges, self._records,
                    self.entry_image):
            if obj is not None:
                obj.release()
        if self.sorter is not None:
            self.sorter.release()
