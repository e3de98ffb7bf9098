"""Viewer timings and image quality (the API behind ``cgh bench-viewer``).

Stages are separated by ``glFinish`` so each time is the stage's own. Load = read (file to
:class:`HairAsset`) + decode and upload (GPU decode of geometry and MLP). Every frame is the
default view (``cgh render``'s: the asset framed, azimuth 0, elevation 10). Each rasterizer first
draws one untimed frame (shader compilation, first use of buffers); then for each budget the frame
is timed by stage, the rasterizers taking turns frame by frame: preprocess (projection, SH colour, keys), sort, then
gather (raster: draw records in sorted order; compute: tile binning) and draw (raster: one pulled
triangle per splat; compute: per-tile blending). Quality: the PSNR (RGB) of each image against
the same rasterizer's full-quality image, and against the reference splatter's full-quality render
of the same view at ``reference_size`` (the torch reference takes minutes for millions of Gaussians
at 1080p on a CPU, so it is compared at a smaller size, the viewer rendering that size too).
The raster path's baselines (:class:`Baselines`): the same splats as instanced quads, a bare
instanced-quad draw with a constant-colour fragment shader straight from the preprocess buffers,
and one from the records. Every frame is drawn by :meth:`viewer.frame.SplatRenderer.frame`, timed
stage by stage through a :class:`StageClock`.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from .bench_motion import animated_runs, bench_clip, format_animated
from .frame import STAGES
from .pipeline import bind, set_uniforms
from .rasterizer import Target
from .sort import GpuRadixSort, cpu_sort

BUDGET_FRACTIONS = (1 / 4, 1 / 8, 1 / 16)  # default budgets, as fractions of the Gaussians
REFERENCE_SIZE = (480, 270)
SAMPLED = (0.25, 0.5, 0.75, 1.0)  # where in an animated clip the appearance is compared with the reference


def _timed(ctx: Any, fn) -> float:
    ctx.finish()
    t0 = time.perf_counter()
    fn()
    ctx.finish()
    return time.perf_counter() - t0


class StageClock:
    """A frame's ``stage`` (:data:`viewer.frame.Stage`) that times each stage between ``glFinish``
    calls; a stage run twice in a frame (the raster re-run of an overflowing view) adds up."""

    def __init__(self, ctx: Any):
        self.ctx = ctx
        self.seconds: dict[str, float] = {}

    def __call__(self, name: str, fn):
        self.ctx.finish()
        t0 = time.perf_counter()
        result = fn()
        self.ctx.finish()
        self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0
        return result


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two images in [0, 1] (``inf`` when equal)."""
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(1.0 / mse)


def _reference_rgb(asset: Any, camera: Any) -> np.ndarray | None:
    """The torch reference splatter's image, or ``None`` without torch."""
    try:
        from training.splatter import render_gaussians
    except ImportError:
        return None
    from cghair_format import decode_gaussians

    return render_gaussians(decode_gaussians(asset), camera)["rgb"]


def benchmark(path: str | None = None, synthetic: int | None = None, points: int = 101, width: int = 1920,
              height: int = 1080, frames: int = 3, sort: str = "auto",
              rasterizers: tuple[str, ...] = ("compute", "raster"),
              budgets: tuple[int, ...] | None = None, reference_size: tuple[int, int] | None = REFERENCE_SIZE,
              ctx: Any = None, animate: bool = False, simulate: bool = False, turn_sh: bool = True) -> dict:
    """Figures in seconds (medians over ``frames``) and dB, plus counts, the OpenGL driver and
    device, and the work-group sizes.

    ``budgets``: Gaussians per frame of the level-of-detail runs (default: 1/4, 1/8 and 1/16 of
    the asset's); ``reference_size``: ``None`` skips the reference splatter. ``animate`` adds the
    animated frame against the static one (:mod:`viewer.bench_motion`, ``"animated"``), with the live
    simulation's cost where ``simulate``, the SH turned with their segments unless ``turn_sh`` is false;
    with the reference too (and a clip, not ``simulate``), the animated frames' appearance (``"psnr"``).
    """
    from cghair_format.camera import Camera

    from .camera_control import OrbitController
    from .context import create_headless_context, gl_info
    from .frame import ViewSettings
    from .renderer import Renderer

    asset, source, file_bytes, t_read = _load(path, synthetic, points)
    own_ctx = ctx is None
    ctx = ctx or create_headless_context()
    ctx.__enter__()  # make it current: another context may have been created since
    if ctx.version_code < 430:
        from .context import GLContextError

        raise GLContextError("bench-viewer measures the GPU pipeline, which needs OpenGL 4.3 compute shaders; "
                             f"this context offers {ctx.version_code / 100:.1f}")
    made: list[Renderer] = []
    animated = animate or simulate
    t_upload = _timed(ctx, lambda: made.append(Renderer.from_asset(ctx, asset, sort=sort, animated=animated,
                                                                               turn_sh=turn_sh)))
    renderer = made[0]
    if budgets is None:
        budgets = tuple(max(1, int(renderer.count * f)) for f in BUDGET_FRACTIONS)
    ctl = OrbitController.framing(*renderer.bounds, asset.up_axis)
    cam = Camera.orbit(ctl.target, ctl.distance, 0.0, 10.0, width, height, asset.up_axis)
    small = reference = t_reference = None
    if reference_size is not None:
        small = Camera.orbit(ctl.target, ctl.distance, 0.0, 10.0, *reference_size, asset.up_axis)
        t0 = time.perf_counter()
        reference = _reference_rgb(asset, small)
        t_reference = time.perf_counter() - t0
    settings = ViewSettings()
    for rasterizer in rasterizers:  # warm-up, untimed: shader compilation, buffers' first use
        renderer.rasterizer, renderer.budget = rasterizer, None
        renderer.render(cam, settings)
    runs = _timed_runs(renderer, cam, settings, rasterizers, (None, *budgets), frames, (small, reference))
    result = {
        "source": source, "file_bytes": file_bytes, "gaussians": renderer.count, "strands": renderer.lod.n_strands,
        "width": width, "height": height, "frames": frames, "renderer": ctx.info.get("GL_RENDERER"),
        "sort_mode": renderer.sort_mode, "read_s": t_read, "decode_upload_s": t_upload,
        "reference_size": list(reference_size) if reference is not None else None,
        "reference_s": t_reference if reference is not None else None,
        "runs": runs, "gl": gl_info(ctx), "workgroups": renderer.programs.workgroups.record(),
    }
    full = {run["rasterizer"]: run["frame_s"] for run in runs if run["budget"] is None}
    if "compute" in full and "raster" in full:
        result["compute_over_raster"] = full["compute"] / full["raster"]  # full quality, same run
    if "raster" in rasterizers:
        result.update(_raster_baselines(renderer, cam, settings, frames))
    if animated:
        from .motion import file_animation

        renderer.rasterizer = rasterizers[0]
        clip = None if simulate else (file_animation(path) if path is not None else None) or bench_clip(asset, frames)
        result["animated"] = animated_runs(renderer, asset, cam, settings, (None, *budgets), frames, StageClock, clip,
                                           simulate)
        if clip is not None and reference is not None:  # the appearance against the CPU's turned SH
            result["animated"]["psnr"] = appearance_psnr(renderer, asset, clip, small)
    renderer.release()
    if own_ctx:
        ctx.release()
    return result


def appearance_psnr(renderer: Any, asset: Any, animation: Any, camera: Any) -> list[dict]:
    """Per sampled frame of ``animation`` (:data:`SAMPLED`), PSNR (RGB, dB) against the native splatter's
    image of ``frame_gaussians(..., turn_sh=True)`` (the CPU's Gaussians, SH turned per segment): of the
    viewer's full-quality frame (SH turned unless the renderer was made with ``turn_sh=False``), and of
    the same splatter with the SH left as at rest. The renderer's cards are left at rest."""
    from cghair_format.animation import frame_gaussians
    from training.backends import default_backend, render_gaussians

    backend = default_backend("cpu")
    last = animation.frames - 1
    rows = []
    for f in sorted({round(x * last) for x in SAMPLED}):
        want, unturned = (render_gaussians(frame_gaussians(asset, animation, f, turn_sh=turn), camera, (0.0, 0.0, 0.0),
                                           "cpu", backend)["rgb"] for turn in (True, False))
        renderer.budget = None
        renderer.move_cards(animation.cards(asset.cards, f))
        rows.append({"frame": f, "viewer_db": psnr(renderer.render(camera)[..., :3], want),
                     "unturned_db": psnr(unturned, want)})
    renderer.move_cards(asset.cards)
    return rows


def _load(path: str | None, synthetic: int | None, points: int) -> tuple[Any, str, int | None, float]:
    """The asset (read from ``path`` or built in memory), its name, file size and read time."""
    import cghair_format

    t0 = time.perf_counter()
    if path is not None:
        asset = cghair_format.read(path)
        return asset, str(path), Path(path).stat().st_size, time.perf_counter() - t0
    from .synthetic import synthetic_asset

    asset = synthetic_asset(synthetic, points=points)
    return asset, f"synthetic {synthetic} x {points}", None, time.perf_counter() - t0


def _timed_runs(renderer: Any, cam: Any, settings: Any, rasterizers: tuple[str, ...], budgets: tuple,
                frames: int, reference: tuple[Any, np.ndarray | None]) -> list[dict]:
    """Per rasterizer and budget: stage medians, what was drawn, and the PSNRs. The rasterizers
    take turns frame by frame, so a change of the machine's load between them (llvmpipe shares
    the CPU) weighs on both alike."""
    runs: dict[str, list[dict]] = {r: [] for r in rasterizers}
    full_images: dict[str, np.ndarray] = {}
    small, reference_rgb = reference
    for budget in budgets:
        rows = {r: {k: [] for k in STAGES} for r in rasterizers}
        images, drawn = {}, {}
        for frame in range(frames):
            for rasterizer in rasterizers:
                renderer.rasterizer, renderer.budget = rasterizer, budget
                clock = StageClock(renderer.ctx)
                renderer.frame(cam, settings, clock)
                for k in STAGES:
                    rows[rasterizer][k].append(clock.seconds[k])
                if frame == frames - 1:
                    images[rasterizer], drawn[rasterizer] = _last_frame(renderer, cam, settings, budget)
        for rasterizer in rasterizers:
            med = {k: statistics.median(v) for k, v in rows[rasterizer].items()}
            image = images[rasterizer]
            full = full_images.setdefault(rasterizer, image)
            run = {**drawn[rasterizer], **{f"{k}_s": v for k, v in med.items()}, "frame_s": sum(med.values()),
                   "psnr_vs_full_db": psnr(image, full) if budget is not None else None,
                   "psnr_vs_reference_db": None}
            if reference_rgb is not None:
                renderer.rasterizer, renderer.budget = rasterizer, budget
                run["psnr_vs_reference_db"] = psnr(renderer.render(small, settings)[..., :3], reference_rgb)
            runs[rasterizer].append(run)
    return [run for r in rasterizers for run in runs[r]]


def _last_frame(renderer: Any, cam: Any, settings: Any, budget: int | None) -> tuple[np.ndarray, dict]:
    """The RGB image of the frame just drawn, and what it drew."""
    renderer.composite(cam, settings)
    image = np.frombuffer(renderer.output(cam.width, cam.height).texture.read(), np.float32)
    tiles = renderer.rasterizers.get("compute")
    return image.reshape(cam.height, cam.width, 4)[..., :3].copy(), {
        "rasterizer": renderer.frame_rasterizer, "budget": budget, "gaussians_drawn": renderer.drawn,
        "strands_drawn": renderer.plan.strands, "visible": renderer.visible,
        "tile_entries": tiles.entries if renderer.frame_rasterizer == "compute" else None}


class Baselines:
    """Cheaper draws of the splats of the renderer's last raster frame, to put its draw time in
    scale: instanced quads at the splats' positions and sizes with a constant-colour fragment
    shader, read through the sort order from the preprocess buffers (no gather needed), or from
    the gathered records, read sequentially (the cheapest instanced-quad draw of these splats)."""

    def __init__(self, renderer: Any):
        self.renderer = renderer
        self.raster = renderer.rasterizer_named("raster")
        programs = renderer.programs
        self.quads = programs.render("bare_quad", "bare_quad")
        self.record_quads = programs.render("splat", "bare_quad")
        self._vao = renderer.ctx.vertex_array(self.quads, [])

    def draw_sorted(self, target: Target, width: int, height: int) -> None:
        ctx, r = self.renderer.ctx, self.renderer
        target.framebuffer.use()
        target.framebuffer.clear(0.0, 0.0, 0.0, 0.0)
        ctx.enable_only(ctx.BLEND)
        ctx.blend_func = ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA
        set_uniforms(self.quads, u_viewport=(float(width), float(height)))
        bind(self.quads, Order=r.values, Center=self.raster.center, Axes=self.raster.axes)
        self._vao.render(mode=ctx.TRIANGLE_STRIP, vertices=4, instances=r.count)

    def draw_records(self, target: Target, width: int, height: int) -> None:
        ctx = self.renderer.ctx
        self.raster.draw_records(target, width, height, self.record_quads, False,
                                 (ctx.SRC_ALPHA, ctx.ONE_MINUS_SRC_ALPHA))

    def release(self) -> None:
        self._vao.release()


def _raster_baselines(renderer: Any, cam: Any, settings: Any, frames: int) -> dict:
    """The raster path at full quality against cheaper draws of the same splats, and both sorts."""
    ctx, count, (width, height) = renderer.ctx, renderer.count, (cam.width, cam.height)
    renderer.rasterizer, renderer.budget = "raster", None
    raster, baselines, target = renderer.rasterizer_named("raster"), Baselines(renderer), renderer.accum(width, height)
    gpu_sorter = renderer.sorter or GpuRadixSort(ctx, renderer.programs, count)
    rows: dict[str, list[float]] = {k: [] for k in ("sort_gpu", "sort_cpu", "draw", "bare", "bare_records",
                                                    "draw_quads")}
    for _ in range(frames):
        for mode, fn in (("gpu", lambda: gpu_sorter.sort(renderer.keys, renderer.values, count)),
                         ("cpu", lambda: cpu_sort(renderer.keys, renderer.values, count))):
            renderer.preprocess(cam, settings)
            rows["sort_" + mode].append(_timed(ctx, fn))
        clock = StageClock(ctx)
        renderer.frame(cam, settings, clock)
        rows["draw"].append(clock.seconds["draw"])
        rows["bare"].append(_timed(ctx, lambda: baselines.draw_sorted(target, width, height)))
        rows["bare_records"].append(_timed(ctx, lambda: baselines.draw_records(target, width, height)))
        primitive, raster.primitive = raster.primitive, "quads"
        rows["draw_quads"].append(_timed(ctx, lambda: raster.draw(target, width, height)))
        raster.primitive = primitive
    baselines.release()
    if gpu_sorter is not renderer.sorter:
        gpu_sorter.release()
    med = {k: statistics.median(v) for k, v in rows.items()}
    return {"sort_gpu_s": med["sort_gpu"], "sort_cpu_s": med["sort_cpu"], "draw_instanced_quads_s": med["draw_quads"],
            "bare_quads_s": med["bare"], "bare_quads_records_s": med["bare_records"],
            "draw_over_bare": med["draw"] / med["bare"], "draw_over_bare_records": med["draw"] / med["bare_records"]}


def format_report(r: dict) -> str:
    ms = lambda s: f"{1000 * s:8.1f}" if s is not None else "     n/a"  # noqa: E731
    db = lambda x: "       -" if x is None else ("     inf" if math.isinf(x) else f"{x:8.2f}")  # noqa: E731
    size = f", {r['file_bytes'] / 1e6:.2f} MB" if r["file_bytes"] else ""
    egl = r["gl"]["egl_device"]
    device = f", EGL device {egl['index']} ({egl['kind']})" if egl else ""
    ref = (f"reference splatter at {r['reference_size'][0]}x{r['reference_size'][1]} "
           f"({r['reference_s']:.1f} s)" if r["reference_size"] else "no reference splatter (needs torch)")
    lines = [
        f"viewer benchmark: {r['source']}{size}, {r['gaussians']:,} Gaussians, {r['width']}x{r['height']}, "
        f"{r['renderer']}, default view, median of {r['frames']} frames, sort {r['sort_mode']}",
        f"device   {r['gl']['vendor']}, OpenGL {r['gl']['version']}{device}; work groups: {r['workgroups']['profile']} "
        f"(tile blend {r['workgroups']['blend'][0]} x {r['workgroups']['blend'][1]})",
        *([f"hint     {r['gl']['hint']}"] if r["gl"]["hint"] else []),
        f"load     read {ms(r['read_s'])} ms   decode+upload (GPU) {ms(r['decode_upload_s'])} ms",
        f"quality  PSNR (RGB) against the same rasterizer at full quality, and against the {ref}",
        "rasterizer     budget      drawn  preproc     sort gath/bin draw/blnd    frame ms    fps  vs full  vs ref",
    ]
    for run in r["runs"]:
        budget = "full" if run["budget"] is None else f"{run['budget']:,}"
        lines.append(f"{run['rasterizer']:<8} {budget:>12} {run['gaussians_drawn']:>10,} {ms(run['preprocess_s'])} "
                     f"{ms(run['sort_s'])} {ms(run['gather_s'])}  {ms(run['draw_s'])}  {ms(run['frame_s'])}   "
                     f"{1 / run['frame_s']:5.2f} {db(run['psnr_vs_full_db'])} {db(run['psnr_vs_reference_db'])}")
    if "compute_over_raster" in r:
        lines.append(f"compute / raster frame time at full quality: {r['compute_over_raster']:.2f}x")
    if "bare_quads_s" in r:
        lines += [
            f"raster   sorts: gpu radix {ms(r['sort_gpu_s'])} ms, cpu numpy {ms(r['sort_cpu_s'])} ms; "
            f"draw as instanced quads {ms(r['draw_instanced_quads_s'])} ms",
            f"baseline bare instanced quads {ms(r['bare_quads_s'])} ms (draw / bare = {r['draw_over_bare']:.2f}x), "
            f"from the gathered records {ms(r['bare_quads_records_s'])} ms ({r['draw_over_bare_records']:.2f}x)",
        ]
    if "animated" in r:
        lines += format_animated(r["animated"])
    return "\n".join(lines)
