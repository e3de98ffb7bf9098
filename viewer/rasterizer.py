"""What a rasterizer is: the stage of a frame after the preprocess and the depth sort.

A rasterizer tells the preprocess where to write the projected splats, then gathers the visible
ones in depth order and splats them into the frame's accumulation target (``C = sum c_i a_i T_i``,
``alpha = 1 - T``, RGBA32F, row ``j`` = image row ``j``). The two implementations:
:class:`viewer.tiles.TileRasterizer` (``compute``: tiles blended in compute shaders) and
:class:`viewer.raster.RecordRasterizer` (``raster``: a triangle per splat, fixed-function
blending). A new one implements this protocol and is named in :data:`viewer.renderer.RASTERIZERS`.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol


class Target(NamedTuple):
    """An accumulation target: an RGBA32F texture and a framebuffer drawing into it."""

    texture: Any
    framebuffer: Any


class Rasterizer(Protocol):
    name: str  # as ``--rasterizer`` names it

    def preprocess_outputs(self, program: Any) -> None:
        """Bind what the preprocess ``program`` writes for this rasterizer, and set its switches."""

    def gather(self, order: Any, visible: int, width: int, height: int) -> bool:
        """Prepare the first ``visible`` splats of the sorted ``order`` buffer for a frame of this
        size; ``False`` if this frame is beyond the rasterizer's capacity (then the renderer draws
        it with another)."""

    def draw(self, target: Target, width: int, height: int) -> None:
        """Splat the gathered splats into ``target`` (overwritten)."""

    def release(self) -> None:
        """Free the rasterizer's GPU objects."""
