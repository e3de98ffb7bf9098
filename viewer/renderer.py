"""The splatting renderer: per-frame preprocess, depth sort, and a rasterizer (headless or window).

Image model: the rendering contract shared with ``training/splatter.py``. Per frame a compute
shader projects every drawn Gaussian (EWA 2D covariance, conic, 3-sigma radius, SH colour, depth
key, the primitive's half-axes) and counts the visible ones; the keys are sorted (GPU radix sort,
or numpy). Then a rasterizer (:mod:`viewer.rasterizer`) writes ``C = sum c_i a_i T_i`` and
``alpha = 1 - T`` into an RGBA32F target:

- ``compute`` (:mod:`viewer.tiles`): the visible splats are binned into 16 x 16 tiles and each
  tile blends its splats front to back in a compute shader, stopping at T < 1e-4;
- ``raster`` (:mod:`viewer.raster`): a gather pass writes the visible splats' draw records in
  sorted order and one triangle (or instanced quad) per splat is drawn front to back with the
  "under" operator (``dst += (1 - dst.a) * (c a, a)``).

A last pass adds the background and the overlays (:class:`viewer.frame.SplatRenderer`). Row ``j``
of the target holds image row ``j`` (image y points down), so reads need no flip. A splat budget
(:mod:`viewer.lod`) draws a stable subset of the strands, compensated to keep the hair's coverage
and colour.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from cghair_format import Cards, Gaussians, HairAsset
from cghair_format.camera import Camera

from .decode import GpuScene, SceneTooLargeError, block_limit, sh_texels, upload_asset, upload_gaussians
from .frame import SplatRenderer, Stage, ViewSettings, run_stage
from .lod import LodPlan, StrandLod
from .pipeline import Programs, bind, dispatch, set_uniforms, use_textures
from .raster import RecordRasterizer, check_primitive
from .rasterizer import Rasterizer
from .shader_constants import SOFTWARE_RENDERERS
from .sort import SORT_MODES, GpuRadixSort, stable_order
from .tiles import TileRasterizer, max_splats

NEAR, FAR = 0.01, 1.0e4  # clip planes of the overlays (the splats use the contract's near plane)
# the rasterizers by their --rasterizer names, each made from its renderer on first use
RASTERIZERS: dict[str, Callable[[Renderer], Rasterizer]] = {
    "compute": lambda r: TileRasterizer(r.ctx, r.programs, max(r.count, 1), capacity=block_limit(r.ctx) // 4,
                                        sort_mode=r.sort_mode),
    "raster": lambda r: RecordRasterizer(r.ctx, r.programs, max(r.count, 1), r.primitive),
}


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


class Renderer(SplatRenderer):
    """Draws one :class:`GpuScene` from any camera with compute shaders (OpenGL 4.3).

    ``sort``: ``"gpu"``, ``"cpu"`` or ``"auto"``; ``rasterizer``: ``"compute"`` (tiles, early
    termination), ``"raster"`` or ``"auto"`` (compute, unless the scene exceeds its record image);
    it may change between frames. ``primitive`` (raster path): ``"triangles"`` or ``"quads"``
    (:class:`viewer.raster.RecordRasterizer`), fixed when the raster path is first used.
    ``budget``: at most this many Gaussians per frame (level of detail), ``None`` for all; it may
    change between frames.
    """

    supports_budget = True
    supports_animation = True

    def __init__(self, ctx: Any, scene: GpuScene, sort: str = "auto", programs: Programs | None = None,
                 primitive: str = "triangles", rasterizer: str = "auto", budget: int | None = None):
        if sort not in (*SORT_MODES, "auto"):
            raise ValueError(f"sort must be one of {(*SORT_MODES, 'auto')}, got {sort!r}")
        if rasterizer not in (*RASTERIZERS, "auto"):
            raise ValueError(f"rasterizer must be one of {(*RASTERIZERS, 'auto')}, got {rasterizer!r}")
        fits = scene.count <= max_splats(ctx)
        if rasterizer == "compute" and not fits:
            scene.release()  # the renderer owns its scene (see release)
            raise SceneTooLargeError(
                f"the compute rasterizer's record image holds {max_splats(ctx):,} Gaussians (GL_MAX_TEXTURE_SIZE); "
                f"this asset has {scene.count:,}: use --rasterizer raster")
        self.primitive = check_primitive(primitive)
        super().__init__(ctx, programs or Programs(ctx))
        n = max(scene.count, 1)
        self.rasterizers: dict[str, Rasterizer] = {}  # made on first use (RASTERIZERS)
        self.rasterizer = ("compute" if fits else "raster") if rasterizer == "auto" else rasterizer
        self.scene = scene
        self.sort_mode = default_sort_mode(ctx) if sort == "auto" else sort
        self.budget = check_budget(budget)
        self.visible_count = ctx.buffer(reserve=4)
        self.visible = 0  # splats in front of the camera and on screen, after the last gather
        self.keys = ctx.buffer(reserve=4 * n)
        self.values = ctx.buffer(reserve=4 * n)  # after the sort: the slots in draw order
        self.sorter = GpuRadixSort(ctx, self.programs, n) if self.sort_mode == "gpu" else None
        self.lod = StrandLod(ctx, scene)
        self.plan: LodPlan = self.lod.plan(None)  # what the last preprocess drew
        self.frame_rasterizer = self.rasterizer  # the last frame's: raster where the tiles overflowed
        self._warned = False
        self._mesh_vao = self._lines_vao = None  # the overlays' vertex arrays, made on first use
        self._decoded = self.lod.n_strands  # strands whose geometry is decoded for the current cards

    def rasterizer_named(self, name: str) -> Rasterizer:
        """The renderer's rasterizer of that name, made on first use."""
        if name not in self.rasterizers:
            if name not in RASTERIZERS:
                raise ValueError(f"rasterizer must be one of {tuple(RASTERIZERS)}, got {name!r}")
            self.rasterizers[name] = RASTERIZERS[name](self)
        return self.rasterizers[name]

    @classmethod
    def from_asset(cls, ctx: Any, asset: HairAsset, sort: str = "auto", primitive: str = "triangles",
                   rasterizer: str = "auto", budget: int | None = None, programs: Programs | None = None,
                   animated: bool = False, turn_sh: bool = True) -> Renderer:
        """``animated``: keep the geometry decode's inputs so that :meth:`move_cards` can move the cards,
        each Gaussian's SH turning with its segment unless ``turn_sh`` is false."""
        programs = programs or Programs(ctx)
        return cls(ctx, upload_asset(ctx, programs, asset, animated, turn_sh), sort, programs, primitive, rasterizer,
                   budget)

    def move_cards(self, cards: Cards, stage: Stage = run_stage) -> None:
        """Put the cards at ``cards`` (an animation's frame; half-widths and groups stay the rest pose's):
        stage ``upload`` writes their spines and normals, ``decode`` rebuilds the card strips, and the
        strand points and Gaussians of the strands the current budget draws, on the GPU. The next
        :meth:`frame` draws them (decoding the others first if its budget draws more)."""
        geometry = self.scene.geometry
        if geometry is None:
            raise ValueError("this renderer was made without animated=True: its cards cannot move")
        stage("upload", lambda: geometry.upload_cards(cards.spine, cards.normal))
        self._decoded = 0
        stage("decode", lambda: self._decode(self.lod.plan(self.budget)))

    def _decode(self, plan: LodPlan) -> None:
        """Decode the geometry of ``plan``'s strands (all where it is full) for the cards uploaded last."""
        lod = None if plan.full else (self.lod.buffer, plan.chunks)
        self.scene.geometry.decode(self.ctx, self.programs, self.scene, lod)
        self._decoded = plan.strands

    def _decode_missing(self, plan: LodPlan, stage: Stage) -> None:
        """Where the cards moved and ``plan`` draws strands not yet decoded for them, decode them."""
        if self.scene.geometry is not None and plan.strands > self._decoded:
            stage("decode", lambda: self._decode(plan))

    @classmethod
    def from_gaussians(cls, ctx: Any, gaussians: Gaussians, sort: str = "auto", primitive: str = "triangles",
                       rasterizer: str = "auto", budget: int | None = None) -> Renderer:
        return cls(ctx, upload_gaussians(ctx, gaussians), sort, primitive=primitive, rasterizer=rasterizer,
                   budget=budget)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.scene.bounds

    @property
    def count(self) -> int:
        return self.scene.count

    @property
    def drawn(self) -> int:
        """Gaussians the last preprocess wrote (all, or the budget's strands')."""
        return self.plan.gaussians

    def describe(self) -> str:
        """What the last frame drew, for the window title: rasterizer, Gaussians, strands."""
        p, total = self.plan, self.scene.count
        drawn = f"{total:,} Gaussians" if p.full else (
            f"{p.gaussians:,} of {total:,} Gaussians ({100 * p.strands / self.lod.n_strands:.0f} % of strands)")
        return f"{self.frame_rasterizer} | {drawn}"

    def frame(self, camera: Camera, settings: ViewSettings | None = None, stage: Stage = run_stage) -> None:
        """Preprocess, sort, gather and draw; a view whose tiles overflow the compute rasterizer is
        drawn with the raster path (preprocessed and sorted again, within the gather stage)."""
        width, height = camera.width, camera.height
        name = self.rasterizer
        self._decode_missing(self.lod.plan(self.budget), stage)
        stage("preprocess", lambda: self.preprocess(camera, settings, name))
        stage("sort", self.sort)
        if not stage("gather", lambda: self._gather(name, width, height)):
            self._warn_overflow()
            name = "raster"
            stage("gather", lambda: (self.preprocess(camera, settings, name), self.sort(),
                                     self._gather(name, width, height)))
        self.frame_rasterizer = name
        stage("draw", lambda: self.rasterizer_named(name).draw(self.accum(width, height), width, height))

    def preprocess(self, camera: Camera, settings: ViewSettings | None = None, rasterizer: str | None = None) -> None:
        """Project, colour and key every drawn Gaussian for ``camera``, writing what ``rasterizer``
        (default: :attr:`rasterizer`) reads."""
        s = settings or ViewSettings()
        scene = self.scene
        prog = self.programs.compute("preprocess")
        self._camera_uniforms(prog, camera, s)
        self.plan = plan = self.lod.plan(self.budget)
        set_uniforms(prog, u_indexed=not plan.full, u_lod_opacity=float(plan.opacity_power),
                     u_lod_width=float(plan.width))
        self.rasterizer_named(rasterizer or self.rasterizer).preprocess_outputs(prog)
        self.visible_count.clear()
        turn = scene.geometry.turn if scene.geometry is not None and s.turn_sh else None
        set_uniforms(prog, u_turn_sh=turn is not None)
        for k, chunk in enumerate(scene.sh):
            # without turns, u_turns is bound to any texture: the shader does not read it
            use_textures(prog, u_means=scene.means, u_rotations=scene.rotations, u_scales=scene.scales,
                         u_sh=chunk.texture, u_turns=scene.rotations if turn is None else turn.turns)
            bind(prog, Keys=self.keys, Values=self.values, StrandCard=scene.strand_card, CardGroup=scene.card_group,
                 Visible=self.visible_count, LodStrands=self.lod.buffer)
            if plan.full:
                set_uniforms(prog, u_base=chunk.first, u_count=chunk.count)
                dispatch(self.ctx, prog, chunk.count)
            else:
                list_base, count, out_base = plan.chunks[k]
                set_uniforms(prog, u_base=chunk.first, u_count=count, u_list_base=list_base, u_out_base=out_base)
                dispatch(self.ctx, prog, count)

    def _camera_uniforms(self, prog: Any, camera: Camera, s: ViewSettings) -> None:
        scene = self.scene
        degree = scene.sh_degree if s.sh_degree is None else max(0, min(int(s.sh_degree), scene.sh_degree))
        w2c = np.asarray(camera.world_to_camera, np.float64)
        set_uniforms(prog, u_trans=tuple(float(x) for x in w2c[:3, 3]),
                     u_cam_center=tuple(float(x) for x in camera.center),
                     u_intrinsics=(float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy)),
                     u_viewport=(float(camera.width), float(camera.height)), u_sh_texels=sh_texels(scene.sh_coeffs),
                     u_degree=degree, u_scale=float(s.splat_scale), u_color_mode=int(s.color_by_group),
                     u_segments=scene.segments)
        prog["u_rot"].write(_mat_bytes(w2c[:3, :3]))

    def sort(self) -> None:
        """Order the splats front to back (values become the draw order)."""
        if self.sorter is not None:
            self.sorter.sort(self.keys, self.values, self.drawn)
        elif self.drawn:
            # the preprocess writes values[slot] = slot, so the sorting permutation is the sorted
            # values: no values to read back, no sorted keys to write (nothing reads them)
            keys = np.frombuffer(self.keys.read(size=4 * self.drawn), np.uint32)
            self.values.write(stable_order(keys).astype(np.uint32).tobytes())

    def _gather(self, name: str, width: int, height: int) -> bool:
        # culled splats carry the largest key, so the visible ones are the first slots
        self.visible = int(np.frombuffer(self.visible_count.read(), np.uint32)[0])
        return self.rasterizer_named(name).gather(self.values, self.visible, width, height)

    def _warn_overflow(self) -> None:
        if not self._warned:
            tiles = self.rasterizer_named("compute")
            warnings.warn(f"this view needs {tiles.entries_needed:,} tile entries, more than the compute "
                          f"rasterizer's {tiles.capacity:,}: drawing it with the raster path instead",
                          RuntimeWarning, stacklevel=3)
            self._warned = True

    def overlays(self, camera: Camera, settings: ViewSettings, flip_y: bool) -> None:
        """Card strips and strand lines, projected like the splats (scenes from assets only)."""
        scene = self.scene
        if scene.points is None:
            return
        if settings.show_strands:
            self._decode_missing(self.lod.plan(None), run_stage)
        prog = self.programs.render("overlay", "overlay")
        proj = projection_matrix(camera)
        if flip_y:
            proj = np.diag([1.0, -1.0, 1.0, 1.0]) @ proj
        prog["u_view"].write(_mat_bytes(camera.world_to_camera))
        prog["u_projection"].write(_mat_bytes(proj))
        self.ctx.enable_only(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
        if settings.show_cards:
            bind(prog, Points=scene.mesh_pos, Groups=scene.card_group)
            set_uniforms(prog, u_mode=1, u_points=scene.card_vertices, u_by_group=settings.color_by_group,
                         u_alpha=0.35)
            if self._mesh_vao is None:
                self._mesh_vao = self.ctx.vertex_array(prog, [], index_buffer=scene.mesh_triangles,
                                                       index_element_size=4)
            self._mesh_vao.render(mode=self.ctx.TRIANGLES, vertices=scene.mesh_triangles.size // 4)
        if settings.show_strands:
            bind(prog, Points=scene.points, Groups=scene.strand_group)
            set_uniforms(prog, u_mode=0, u_points=scene.segments + 1, u_by_group=settings.color_by_group,
                         u_alpha=0.8)
            if self._lines_vao is None:
                self._lines_vao = self.ctx.vertex_array(prog, [])
            self._lines_vao.render(mode=self.ctx.LINES, vertices=2 * scene.count)

    def release(self) -> None:
        for obj in (self.keys, self.values, self.visible_count, self._mesh_vao, self._lines_vao):
            if obj is not None:
                obj.release()
        for rasterizer in self.rasterizers.values():
            rasterizer.release()
        self.lod.release()
        if self.sorter is not None:
            self.sorter.release()
        super().release()
        self.scene.release()


def create_renderer(ctx: Any, asset: HairAsset, sort: str = "auto", primitive: str = "triangles",
                    rasterizer: str = "auto", budget: int | None = None, animated: bool = False,
                    turn_sh: bool = True) -> SplatRenderer:
    """The GPU renderer where compute shaders exist (OpenGL 4.3), else the numpy fallback.

    The compute rasterizer, splat budgets and moving cards (``animated``, the SH turning with their
    segments unless ``turn_sh`` is false) need compute shaders: asking for them on OpenGL 3.3 is a
    :class:`GLContextError` that says so.
    """
    if ctx.version_code >= 430:
        return Renderer.from_asset(ctx, asset, sort=sort, primitive=primitive, rasterizer=rasterizer,
                                   budget=budget, animated=animated, turn_sh=turn_sh)
    from .context import GLContextError
    from .fallback import FallbackRenderer

    offered = f"this OpenGL offers {ctx.version_code / 100:.1f}"
    if rasterizer == "compute":
        raise GLContextError(f"--rasterizer compute needs OpenGL 4.3 compute shaders; {offered}: "
                             "use --rasterizer raster or auto")
    if budget is not None:
        raise GLContextError(f"--budget needs OpenGL 4.3 compute shaders; {offered}: leave --budget out")
    if animated:
        raise GLContextError(f"playing hair that moves needs OpenGL 4.3 compute shaders; {offered}: "
                             "render its rest pose (leave out --frames, --animate and --simulate)")
    return FallbackRenderer.from_asset(ctx, asset)
