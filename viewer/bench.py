"""Viewer timings (the API behind ``cgh bench-viewer``).

Stages are separated by ``glFinish`` so each time is the stage's own. Load = read (file to
:class:`HairAsset`) + decode and upload (GPU decode of geometry and MLP). Per frame: preprocess
(projection, SH colour, keys), sort, gather (draw records in sorted order) and draw, the splats
drawn as one pulled triangle each (faster on llvmpipe; the same splats as instanced quads are
timed too). The baseline draws instanced quads of the same positions and sizes with a
constant-colour fragment shader, straight from the preprocess buffers, with no sort or gather;
a second, stricter baseline draws those quads from the gathered records (sequential reads).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Any

from .sort import GpuRadixSort, cpu_sort


def _timed(ctx: Any, fn) -> float:
    ctx.finish()
    t0 = time.perf_counter()
    fn()
    ctx.finish()
    return time.perf_counter() - t0


def benchmark(path: str | None = None, synthetic: int | None = None, points: int = 101, width: int = 1920,
              height: int = 1080, frames: int = 3, sort: str = "auto", ctx: Any = None) -> dict:
    """Figures in seconds (medians over ``frames``), plus counts and the GL renderer's name."""
    import cghair_format
    from cghair_format.camera import Camera

    from .context import create_headless_context
    from .renderer import Renderer, ViewSettings

    t0 = time.perf_counter()
    if path is not None:
        asset = cghair_format.read(path)
        source, file_bytes = str(path), Path(path).stat().st_size
    else:
        from .synthetic import synthetic_asset

        asset = synthetic_asset(synthetic, points=points)
        source, file_bytes = f"synthetic {synthetic} x {points}", None
    t_read = time.perf_counter() - t0
    own_ctx = ctx is None
    ctx = ctx or create_headless_context()
    ctx.__enter__()  # make it current: another context may have been created since
    if ctx.version_code < 430:
        from .context import GLContextError

        raise GLContextError("bench-viewer measures the GPU pipeline, which needs OpenGL 4.3 compute shaders; "
                             f"this context offers {ctx.version_code / 100:.1f}")
    renderer: Renderer | None = None

    def load():
        nonlocal renderer
        renderer = Renderer.from_asset(ctx, asset, sort=sort)

    t_upload = _timed(ctx, load)
    scene = renderer.scene
    lo, hi = scene.bounds
    from .camera_control import OrbitController

    ctl = OrbitController.framing(lo, hi, asset.up_axis)
    settings = ViewSettings()
    gpu_sorter = renderer.sorter or GpuRadixSort(ctx, renderer.programs, scene.count)
    keys = ("preprocess", "sort", "gather", "draw", "sort_gpu", "sort_cpu", "bare", "bare_records", "draw_quads")
    rows: dict[str, list[float]] = {k: [] for k in keys}
    for i in range(frames):
        cam = Camera.orbit(ctl.target, ctl.distance, 360.0 * i / frames, 10.0, width, height, asset.up_axis)
        # the other sort first, on freshly preprocessed keys, so both sorts see the same input
        renderer.preprocess(cam, settings)
        if renderer.sort_mode == "gpu":
            rows["sort_cpu"].append(_timed(ctx, lambda: cpu_sort(renderer.keys, renderer.values, scene.count)))
        else:
            rows["sort_gpu"].append(_timed(ctx, lambda: gpu_sorter.sort(renderer.keys, renderer.values,
                                                                        scene.count)))
        rows["preprocess"].append(_timed(ctx, lambda c=cam: renderer.preprocess(c, settings)))
        rows["sort"].append(_timed(ctx, renderer.sort))
        rows["sort_" + renderer.sort_mode].append(rows["sort"][-1])
        rows["gather"].append(_timed(ctx, renderer.gather))
        rows["draw"].append(_timed(ctx, lambda: renderer.draw(width, height)))
        rows["bare"].append(_timed(ctx, lambda: renderer.draw(width, height, bare="sorted")))
        rows["bare_records"].append(_timed(ctx, lambda: renderer.draw(width, height, bare="records")))
        rows["draw_quads"].append(_timed(ctx, lambda: renderer.draw(width, height, triangles=False)))
    med = {k: statistics.median(v) for k, v in rows.items() if v}
    frame = med["preprocess"] + med["sort"] + med["gather"] + med["draw"]
    result = {
        "source": source, "file_bytes": file_bytes, "gaussians": scene.count, "width": width, "height": height,
        "frames": frames, "renderer": ctx.info.get("GL_RENDERER"), "sort_mode": renderer.sort_mode,
        "read_s": t_read, "decode_upload_s": t_upload, "preprocess_s": med["preprocess"], "sort_s": med["sort"],
        "gather_s": med["gather"],
        "sort_gpu_s": med.get("sort_gpu"), "sort_cpu_s": med.get("sort_cpu"), "draw_s": med["draw"],
        "draw_instanced_quads_s": med["draw_quads"],
        "frame_s": frame, "bare_quads_s": med["bare"], "frame_over_bare": frame / med["bare"],
        "bare_quads_records_s": med["bare_records"], "frame_over_bare_records": frame / med["bare_records"],
    }
    if gpu_sorter is not renderer.sorter:
        gpu_sorter.release()
    renderer.release()
    if own_ctx:
        ctx.release()
    return result


def format_report(r: dict) -> str:
    ms = lambda s: f"{1000 * s:9.1f} ms" if s is not None else "      n/a"  # noqa: E731
    size = f", {r['file_bytes'] / 1e6:.2f} MB" if r["file_bytes"] else ""
    return "\n".join([
        f"viewer benchmark: {r['source']}{size}, {r['gaussians']:,} Gaussians, {r['width']}x{r['height']}, "
        f"{r['renderer']}, median of {r['frames']} frames",
        f"load     read {ms(r['read_s'])}   decode+upload (GPU) {ms(r['decode_upload_s'])}",
        f"frame    preprocess {ms(r['preprocess_s'])}   sort ({r['sort_mode']}) {ms(r['sort_s'])}   "
        f"gather {ms(r['gather_s'])}   draw {ms(r['draw_s'])}",
        f"         total {ms(r['frame_s'])}  ({1 / r['frame_s']:.2f} fps)",
        f"draw     as instanced quads instead of triangles {ms(r['draw_instanced_quads_s'])}",
        f"sorts    gpu radix {ms(r['sort_gpu_s'])}   cpu numpy {ms(r['sort_cpu_s'])}",
        f"baseline bare instanced quads {ms(r['bare_quads_s'])}   frame / bare = {r['frame_over_bare']:.2f}x",
        f"         bare instanced quads from the gathered records {ms(r['bare_quads_records_s'])}   "
        f"frame / that = {r['frame_over_bare_records']:.2f}x",
    ])
