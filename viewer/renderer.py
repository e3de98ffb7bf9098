"""The splatting renderer: per-frame preprocess, depth sort, gather and splat (headless or window).

Image model: the rendering contract shared with ``training/splatter.py``. Per frame a compute
shader projects every drawn Gaussian (EWA 2D covariance, conic, 3-sigma radius, SH colour, depth
key, the primitive's half-axes) and counts the visible ones; the keys are sorted (GPU radix sort,
or numpy). Then one of two rasterizers writes ``C = sum c_i a_i T_i`` and ``alpha = 1 - T`` into
an RGBA32F target:

- ``compute`` (:mod:`viewer.tiles`): the visible splats are binned into 16 x 16 tiles and each
  tile blends its splats front to back in a compute shader, stopping at T < 1e-4;
- ``raster``: a gather pass writes the visible splats' draw records in sorted order and one
  triangle (or instanced quad) per splat is drawn front to back with the "under" operator
  (``dst += (1 - dst.a) * (c a, a)``).

A last pass adds the background and the overlays. Row ``j`` of the target holds image row ``j``
(image y points down), so reads need no flip. A splat budget (:mod:`viewer.lod`) draws a stable
subset of the strands, compensated to keep the hair's coverage and colour.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from cghair_format import Gaussians, HairAsset
from cghair_format.camera import Camera

from .context import check_gl, park_framebuffer
from .decode import GpuScene, SceneTooLargeError, block_limit, sh_texels, upload_asset, upload_gaussians
from .lod import LodPlan, StrandLod
from .pipeline import Programs, bind, dispatch, set_uniforms
from .sort import SORT_MODES, GpuRadixSort, stable_order
from .tiles import TileBinner, max_splats

NEAR, FAR = 0.01, 1.0e4  # clip planes of the overlays (the splats use the contract's near plane)
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast")
# splat primitives: one triangle per splat pulled by gl_VertexID, or an instanced quad
PRIMITIVES = ("triangles", "quads")
MAX_TARGET_SIZES = 2  # render target sizes kept allocated at once
RECORD_BYTES = 64  # per sorted splat: 4 vec4s (splat_records.comp.glsl)
RASTERIZERS = ("compute", "raster")
SH_UNIT = 2  # texture unit of the SH chunk the preprocess reads
MEANS_UNIT = 3  # texture units of the Gaussians' means, rotations and scales


@dataclass
class ViewSettings:
    """What the viewer's toggles change."""

    sh_degree: int | None = None  # None: the file's degree
    splat_scale: float = 1.0
    color_by_group: bool = False
    show_cards: bool = False
    show_strands: bool = False
    hide_splats: bool = False
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)


def default_sort_mode(ctx: Any) -> str:
    """``gpu`` on hardware; ``cpu`` on software renderers, where numpy's sort is measured faster."""
    name = str(ctx.info.get("GL_RENDERER", "")).lower()
    return "cpu" if any(s in name for s in SOFTWARE_RENDERERS) else "gpu"


def projection_matrix(camera: Camera) -> np.ndarray:
    """OpenCV camera coordinates to clip space, keeping image row j at framebuffer row j."""
    w, h = camera.width, camera.height
    return np.array([
        [2 * camera.fx / w, 0, 2 * camera.cx / w - 1, 0],
        [0, 2 * camera.fy / h, 2 * camera.cy / h - 1, 0],
        [0, 0, (FAR + NEAR) / (FAR - NEAR), -2 * FAR * NEAR / (FAR - NEAR)],
        [0, 0, 1, 0]], np.float64)


def _mat_bytes(m: np.ndarray) -> bytes:
    """A matrix as the column-major float32 bytes GLSL expects."""
    return np.ascontiguousarray(np.asarray(m, np.float64).T, np.float32).tobytes()


def check_budget(budget: int | None) -> int | None:
    """A splat budget (Gaussians per frame) or ``None`` (all); raises ``ValueError`` otherwise."""
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, (int, np.integer))
                               or budget < 1):
        raise ValueError(f"the splat budget must be a positive number of Gaussians, got {budget!r}")
    return None if budget is None else int(budget)


class Renderer:
    """Draws one :class:`GpuScene` from any camera.

    ``sort``: ``"gpu"``, ``"cpu"`` or ``"auto"``; ``rasterizer``: ``"compute"`` (tiles, early
    termination), ``"raster"`` or ``"auto"`` (compute, unless the scene exceeds its record image);
    ``primitive`` (raster path): ``"triangles"`` (one triangle per splat, fewer primitives: faster
    on llvmpipe with many splats) or ``"quads"`` (instanced). ``budget``: at most this many
    Gaussians per frame (level of detail), ``None`` for all; it may change between frames.
    """

    def __init__(self, ctx: Any, scene: GpuScene, sort: str = "auto", programs: Programs | None = None,
                 primitive: str = "triangles", rasterizer: str = "auto", budget: int | None = None):
        if sort not in (*SORT_MODES, "auto"):
            raise ValueError(f"sort must be one of {(*SORT_MODES, 'auto')}, got {sort!r}")
        if primitive not in PRIMITIVES:
            raise ValueError(f"primitive must be one of {PRIMITIVES}, got {primitive!r}")
        if rasterizer not in (*RASTERIZERS, "auto"):
            raise ValueError(f"rasterizer must be one of {(*RASTERIZERS, 'auto')}, got {rasterizer!r}")
        fits = scene.count <= max_splats(ctx)
        if rasterizer == "compute" and not fits:
            scene.release()  # the renderer owns its scene (see release)
            raise SceneTooLargeError(
                f"the compute rasterizer's record image holds {max_splats(ctx):,} Gaussians (GL_MAX_TEXTURE_SIZE); "
                f"this asset has {scene.count:,}: use --rasterizer raster")
        self.rasterizer = ("compute" if fits else "raster") if rasterizer == "auto" else rasterizer
        self.ctx = ctx
        self.scene = scene
        self.programs = programs or Programs(ctx)
        self.sort_mode = default_sort_mode(ctx) if sort == "auto" else sort
        self.triangles = primitive == "triangles"
        self.budget = check_budget(budget)
        n = max(scene.count, 1)
        self.center = ctx.buffer(reserve=16 * n)
        self.conic = ctx.buffer(reserve=16 * n)
        self.color = ctx.buffer(reserve=16 * n)
        self.axes = ctx.buffer(reserve=16 * n)
        self.visible_count = ctx.buffer(reserve=4)
        self.visible = 0  # splats in front of the camera and on screen, after gather()
        self.records_per_chunk = max(1, min(n, block_limit(ctx) // RECORD_BYTES))
        self.records: list[Any] = []  # the raster path's draw records, allocated on first use
        self.keys = ctx.buffer(reserve=4 * n)
        self.values = ctx.buffer(reserve=4 * n)
        self.sorter = GpuRadixSort(ctx, self.programs, n) if self.sort_mode == "gpu" else None
        self.lod = StrandLod(ctx, scene)
        self.plan: LodPlan = self.lod.plan(None)  # what the last preprocess drew
        self.binner = TileBinner(ctx, self.programs, n, capacity=block_limit(ctx) // 4, sort_mode=self.sort_mode)
        self.frame_rasterizer = self.rasterizer  # the last frame's: raster where the tiles overflowed
        self._view: tuple[Camera, ViewSettings | None] | None = None  # the last preprocess's camera, settings
        self._size = (0, 0)
        self._targets: dict[tuple[int, int], tuple[Any, Any, Any, Any]] = {}
        self._empty_vao: dict[str, Any] = {}
        self._mesh_vao = None
        self._warned = False

    @classmethod
    def from_asset(cls, ctx: Any, asset: HairAsset, sort: str = "auto", primitive: str = "triangles",
                   rasterizer: str = "auto", budget: int | None = None) -> Renderer:
        programs = Programs(ctx)
        return cls(ctx, upload_asset(ctx, programs, asset), sort, programs, primitive, rasterizer, budget)

    @classmethod
    def from_gaussians(cls, ctx: Any, gaussians: Gaussians, sort: str = "auto", primitive: str = "triangles",
                       rasterizer: str = "auto", budget: int | None = None) -> Renderer:
        return cls(ctx, upload_gaussians(ctx, gaussians), sort, primitive=primitive, rasterizer=rasterizer,
                   budget=budget)

    def describe(self) -> str:
        """What the last frame drew, for the window title: rasterizer, Gaussians, strands."""
        p, total = self.plan, self.scene.count
        drawn = f"{total:,} Gaussians" if p.full else (
            f"{p.gaussians:,} of {total:,} Gaussians ({100 * p.strands / self.lod.n_strands:.0f} % of strands)")
        return f"{self.frame_rasterizer} | {drawn}"

    # -- the per-frame stages, separable for timing ------------------------------------------------

    def preprocess(self, camera: Camera, settings: ViewSettings | None = None) -> None:
        """Project, colour and key every Gaussian for ``camera``."""
        self._view = (camera, settings)
        self._preprocess(camera, settings, records=self.rasterizer == "compute")

    def _preprocess(self, camera: Camera, settings: ViewSettings | None, records: bool) -> None:
        """The preprocess, writing the compute rasterizer's records or the raster path's buffers."""
        s = settings or ViewSettings()
        scene = self.scene
        degree = scene.sh_degree if s.sh_degree is None else max(0, min(int(s.sh_degree), scene.sh_degree))
        prog = self.programs.compute("preprocess")
        w2c = np.asarray(camera.world_to_camera, np.float64)
        set_uniforms(prog, u_trans=tuple(float(x) for x in w2c[:3, 3]),
                     u_cam_center=tuple(float(x) for x in camera.center),
                     u_intrinsics=(float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy)),
                     u_viewport=(float(camera.width), float(camera.height)), u_sh_texels=sh_texels(scene.sh_coeffs),
                     u_sh=SH_UNIT, u_means=MEANS_UNIT, u_rotations=MEANS_UNIT + 1, u_scales=MEANS_UNIT + 2,
                     u_degree=degree, u_scale=float(s.splat_scale), u_color_mode=int(s.color_by_group),
                     u_segments=scene.segments)
        prog["u_rot"].write(_mat_bytes(w2c[:3, :3]))
        self.plan = plan = self.lod.plan(self.budget)
        self._size = (int(camera.width), int(camera.height))
        set_uniforms(prog, u_indexed=not plan.full, u_lod_opacity=float(plan.opacity_power),
                     u_lod_width=float(plan.width), u_write_records=records, u_write_buffers=not records)
        for unit, image in enumerate((scene.means, scene.rotations, scene.scales), MEANS_UNIT):
            image.use(unit)
        if records:
            self.binner.records.bind_to_image(1, read=False, write=True)
        self.visible_count.clear()
        for k, chunk in enumerate(scene.sh):
            chunk.texture.use(SH_UNIT)
            bind(None, None, None, None, self.center, self.conic,
                 self.color, self.keys, self.values, scene.strand_card, scene.card_group, self.axes,
                 self.visible_count, self.lod.buffer)
            if plan.full:
                set_uniforms(prog, u_base=chunk.first, u_count=chunk.count)
                dispatch(self.ctx, prog, chunk.count)
            else:
                list_base, count, out_base = plan.chunks[k]
                set_uniforms(prog, u_base=chunk.first, u_count=count, u_list_base=list_base, u_out_base=out_base)
                dispatch(self.ctx, prog, count)

    @property
    def drawn(self) -> int:
        """Gaussians the last preprocess wrote (all, or the budget's strands')."""
        return self.plan.gaussians

    def sort(self) -> None:
        """Order the splats front to back (values become the draw order)."""
        if self.sorter is not None:
            self.sorter.sort(self.keys, self.values, self.drawn)
        elif self.drawn:
            # the preprocess writes values[slot] = slot, so the sorting permutation is the sorted
            # values: no values to read back, no sorted keys to write (nothing reads them)
            keys = np.frombuffer(self.keys.read(size=4 * self.drawn), np.uint32)
            self.values.write(stable_order(keys).astype(np.uint32).tobytes())

    def gather(self) -> None:
        """After :meth:`sort`: bin the visible splats into tiles (compute rasterizer), or write
        their draw records in sorted order (raster path, and views whose tiles overflow)."""
        # culled splats carry the largest key, so the visible ones are the first slots
        self.visible = int(np.frombuffer(self.visible_count.read(), np.uint32)[0])
        self.frame_rasterizer = self.rasterizer
        if self.rasterizer == "compute":
            if self.binner.bin(self.values, self.visible, *self._size):
                return
            self.frame_rasterizer = "raster"
            if not self._warned:
                warnings.warn(f"this view needs {self.binner.entries_needed:,} tile entries, more than the compute "
                              f"rasterizer's {self.binner.capacity:,}: drawing it with the raster path instead",
                              RuntimeWarning, stacklevel=2)
                self._warned = True
            self._preprocess(*self._view, records=False)  # the raster path's buffers, sorted again
            self.sort()
        self._gather_records()

    def _gather_records(self) -> None:
        if not self.records:
            n = max(self.scene.count, 1)
            self.records = [self.ctx.buffer(reserve=RECORD_BYTES * min(self.records_per_chunk, n - first))
                            for first in range(0, n, self.records_per_chunk)]
        prog = self.programs.compute("splat_records")
        for k, records in enumerate(self.records):
            first = k * self.records_per_chunk
            count = max(0, min(self.records_per_chunk, self.visible - first))
            bind(self.values, self.center, self.conic, self.color, self.axes, records)
            set_uniforms(prog, u_first=first, u_count=count)
            dispatch(self.ctx, prog, count)

    def draw(self, width: int, height: int, bare: str | None = None, triangles: bool | None = None) -> None:
        """Splat the gathered splats into the accumulation target of this size (overwritten): blend
        the tiles (compute rasterizer) or draw the records (raster path).

        ``bare`` draws the benchmark's baselines instead: instanced quads of the same positions and
        sizes with a constant-colour fragment shader, either ``"sorted"`` (read through the sort
        order from the preprocess buffers, no gather needed) or ``"records"`` (from the gathered
        records, read sequentially: the cheapest instanced-quad draw of these splats).
        """
        triangles = self.triangles if triangles is None else triangles
        accum_tex, accum_fbo = self._target(width, height)[:2]
        if bare is None and self.frame_rasterizer == "compute":
            self.binner.blend(accum_tex, width, height)
            return
        accum_fbo.use()
        accum_fbo.clear(0.0, 0.0, 0.0, 0.0)
        if self.scene.count == 0:
            return
        if not self.records:
            raise ValueError("draw the raster path after a raster gather (rasterizer='raster')")
        self.ctx.enable_only(self.ctx.BLEND)
        if bare not in (None, "sorted", "records"):
            raise ValueError(f"bare must be None, 'sorted' or 'records', got {bare!r}")
        if bare == "sorted":
            prog = self.programs.render("bare_quad", "bare_quad")
            set_uniforms(prog, u_viewport=(float(width), float(height)))
            bind(self.values, self.center, None, None, self.axes)
            self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
            self._vao(prog).render(mode=self.ctx.TRIANGLE_STRIP, vertices=4, instances=self.scene.count)
            return
        if bare == "records":
            prog = self.programs.render("splat", "bare_quad")
            triangles = False
            self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
        else:
            prog = self.programs.render("splat", "splat")
            self.ctx.blend_func = self.ctx.ONE_MINUS_DST_ALPHA, self.ctx.ONE
        set_uniforms(prog, u_viewport=(float(width), float(height)), u_triangles=triangles)
        for k, records in enumerate(self.records):
            count = min(self.records_per_chunk, self.visible - k * self.records_per_chunk)
            if count <= 0:
                break
            bind(records)
            if triangles:
                self._vao(prog).render(mode=self.ctx.TRIANGLES, vertices=3 * count)
            else:
                self._vao(prog).render(mode=self.ctx.TRIANGLE_STRIP, vertices=4, instances=count)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA

    def composite(self, camera: Camera, settings: ViewSettings, target: Any = None,
                  flip_y: bool = False) -> None:
        """Background behind the splats, then overlays, into ``target`` (default: the output FBO)."""
        accum_tex, _, _, out_fbo = self._target(camera.width, camera.height)
        fbo = target or out_fbo
        fbo.use()
        self.ctx.disable(self.ctx.BLEND)
        prog = self.programs.render("composite", "composite")
        accum_tex.use(0)
        set_uniforms(prog, u_accum=0, u_background=tuple(float(c) for c in settings.background),
                     u_flip_y=flip_y)
        if settings.hide_splats:
            fbo.clear(*settings.background, 0.0)
        else:
            self._vao(prog).render(mode=self.ctx.TRIANGLES, vertices=3)
        if settings.show_cards or settings.show_strands:
            self._overlays(camera, settings, flip_y)

    def render(self, camera: Camera, settings: ViewSettings | None = None) -> np.ndarray:
        """The image ``[H, W, 4]`` float32 (RGB with background, and alpha) seen by ``camera``."""
        s = settings or ViewSettings()
        if not s.hide_splats:
            self.preprocess(camera, s)
            self.sort()
            self.gather()
            self.draw(camera.width, camera.height)
        else:
            self._target(camera.width, camera.height)[1].clear(0.0, 0.0, 0.0, 0.0)
        self.composite(camera, s)
        out_tex = self._target(camera.width, camera.height)[2]
        image = np.frombuffer(out_tex.read(), np.float32).reshape(camera.height, camera.width, 4)
        check_gl(self.ctx, "render")
        return image.copy()

    # -- helpers ---------------------------------------------------------------------------------------

    def _target(self, width: int, height: int) -> tuple[Any, Any, Any, Any]:
        key = (int(width), int(height))
        if key not in self._targets and len(self._targets) >= MAX_TARGET_SIZES:  # e.g. a resized window
            park_framebuffer(self.ctx)
            for obj in self._targets.pop(next(iter(self._targets))):
                obj.release()
        if key not in self._targets:
            accum = self.ctx.texture(key, 4, dtype="f4")
            out = self.ctx.texture(key, 4, dtype="f4")
            self._targets[key] = (accum, self.ctx.framebuffer([accum]), out, self.ctx.framebuffer([out]))
        return self._targets[key]

    def _vao(self, program: Any) -> Any:
        key = str(id(program))
        if key not in self._empty_vao:
            self._empty_vao[key] = self.ctx.vertex_array(program, [])
        return self._empty_vao[key]

    def _overlays(self, camera: Camera, settings: ViewSettings, flip_y: bool) -> None:
        scene = self.scene
        if scene.points is None:
            return
        prog = self.programs.render("overlay", "overlay")
        proj = projection_matrix(camera)
        if flip_y:
            proj = np.diag([1.0, -1.0, 1.0, 1.0]) @ proj
        prog["u_view"].write(_mat_bytes(camera.world_to_camera))
        prog["u_projection"].write(_mat_bytes(proj))
        self.ctx.enable_only(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
        if settings.show_cards:
            bind(scene.mesh_pos, scene.card_group)
            set_uniforms(prog, u_mode=1, u_points=scene.card_vertices, u_by_group=settings.color_by_group,
                         u_alpha=0.35)
            if self._mesh_vao is None:
                self._mesh_vao = self.ctx.vertex_array(prog, [], index_buffer=scene.mesh_triangles,
                                                       index_element_size=4)
            self._mesh_vao.render(mode=self.ctx.TRIANGLES, vertices=scene.mesh_triangles.size // 4)
        if settings.show_strands:
            bind(scene.points, scene.strand_group)
            set_uniforms(prog, u_mode=0, u_points=scene.segments + 1, u_by_group=settings.color_by_group,
                         u_alpha=0.8)
            self._vao(prog).render(mode=self.ctx.LINES, vertices=2 * scene.count)

    def release(self) -> None:
        for buf in (self.center, self.conic, self.color, self.axes, self.keys, self.values, self.visible_count,
                    *self.records):
            buf.release()
        self.lod.release()
        self.binner.release()
        if self.sorter is not None:
            self.sorter.release()
        if self._targets:
            park_framebuffer(self.ctx)
        for accum, accum_fbo, out, out_fbo in self._targets.values():
            for obj in (accum_fbo, accum, out_fbo, out):
                obj.release()
        self._targets.clear()
        self.scene.release()
