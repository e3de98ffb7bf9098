"""The raster path: a triangle (or instanced quad) per splat, blended front to back by the
fixed-function pipeline with the "under" operator (``dst += (1 - dst.a) * (c a, a)``).

After the depth sort a gather pass (``splat_records``) writes each visible splat's draw record in
sorted order, so the vertex shader reads memory sequentially (random reads had cost llvmpipe's
vertex stage a third of its time). Records are split over buffers of at most one storage block.
"""

from __future__ import annotations

from typing import Any

from .decode import block_limit
from .pipeline import Programs, bind, dispatch, set_uniforms
from .rasterizer import Target
from .shader_constants import RECORD_VEC4S

RECORD_BYTES = 16 * RECORD_VEC4S  # per sorted splat (splat_records.comp.glsl)
# splat primitives: one triangle per splat pulled by gl_VertexID, or an instanced quad
PRIMITIVES = ("triangles", "quads")


def check_primitive(primitive: str) -> str:
    """``primitive`` if it names one of :data:`PRIMITIVES`; raises ``ValueError`` otherwise."""
    if primitive not in PRIMITIVES:
        raise ValueError(f"primitive must be one of {PRIMITIVES}, got {primitive!r}")
    return primitive


class RecordRasterizer:
    """The raster path of one renderer (a :class:`viewer.rasterizer.Rasterizer`).

    ``primitive``: ``"triangles"`` (fewer primitives: faster on llvmpipe with many splats) or
    ``"quads"``; it may change between frames.
    """

    name = "raster"

    def __init__(self, ctx: Any, programs: Programs, splats: int, primitive: str = "triangles"):
        self.ctx = ctx
        self.programs = programs
        self.primitive = check_primitive(primitive)
        self.splats = n = max(splats, 1)
        # what the preprocess writes per splat: centre (mx, my, z, radius), conic and opacity,
        # colour, the primitive's half-axes
        self.center, self.conic, self.color, self.axes = (ctx.buffer(reserve=16 * n) for _ in range(4))
        self.records_per_chunk = max(1, min(n, block_limit(ctx) // RECORD_BYTES))
        self.records: list[Any] = []  # allocated by the first gather
        self.visible = 0
        self._vaos: dict[int, Any] = {}

    def preprocess_outputs(self, program: Any) -> None:
        """The preprocess writes the per-splat buffers (and not the record image)."""
        bind(program, Center=self.center, Conic=self.conic, Color=self.color, Axes=self.axes)
        set_uniforms(program, u_write_records=False, u_write_buffers=True)

    def gather(self, order: Any, visible: int, width: int, height: int) -> bool:
        """Write the draw records of the first ``visible`` splats of ``order``, in that order."""
        if not self.records:
            self.records = [self.ctx.buffer(reserve=RECORD_BYTES * min(self.records_per_chunk, self.splats - first))
                            for first in range(0, self.splats, self.records_per_chunk)]
        self.visible = visible
        prog = self.programs.compute("splat_records")
        for k, records in enumerate(self.records):
            first = k * self.records_per_chunk
            count = max(0, min(self.records_per_chunk, visible - first))
            bind(prog, Order=order, Center=self.center, Conic=self.conic, Color=self.color, Axes=self.axes,
                 Records=records)
            set_uniforms(prog, u_first=first, u_count=count)
            dispatch(self.ctx, prog, count)
        return True

    def draw(self, target: Target, width: int, height: int) -> None:
        """Draw the records front to back with the "under" operator."""
        self.draw_records(target, width, height, self.programs.render("splat", "splat"),
                          self.primitive == "triangles", (self.ctx.ONE_MINUS_DST_ALPHA, self.ctx.ONE))

    def draw_records(self, target: Target, width: int, height: int, program: Any, triangles: bool,
                     blend: tuple[int, int]) -> None:
        """Clear ``target`` and draw the gathered records with ``program`` (a vertex shader that
        reads ``Records``) and the blend function ``blend``: the splats, or the benchmark's
        baseline over the same records (:mod:`viewer.bench`)."""
        target.framebuffer.use()
        target.framebuffer.clear(0.0, 0.0, 0.0, 0.0)
        self.ctx.enable_only(self.ctx.BLEND)
        self.ctx.blend_func = blend
        set_uniforms(program, u_viewport=(float(width), float(height)), u_triangles=triangles)
        vao = self._vao(program)
        for k, records in enumerate(self.records):
            count = min(self.records_per_chunk, self.visible - k * self.records_per_chunk)
            if count <= 0:
                break
            bind(program, Records=records)
            if triangles:
                vao.render(mode=self.ctx.TRIANGLES, vertices=3 * count)
            else:
                vao.render(mode=self.ctx.TRIANGLE_STRIP, vertices=4, instances=count)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA

    def _vao(self, program: Any) -> Any:
        """A vertex array without attributes (the vertex shaders pull their data) for ``program``."""
        key = id(program)
        if key not in self._vaos:
            self._vaos[key] = self.ctx.vertex_array(program, [])
        return self._vaos[key]

    def release(self) -> None:
        for obj in (self.center, self.conic, self.color, self.axes, *self.records, *self._vaos.values()):
            obj.release()
