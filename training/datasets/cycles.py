"""Ground truth rendered by Blender Cycles: strands as curves with the Principled Hair BSDF.

Blender runs in a subprocess (``python training/datasets/_bpy_worker/render_cycles.py JOB``, with the interpreter that
has bpy, usually ``.venv/blender``) so that a crash or a hang
in bpy cannot take the caller down; the job (points, radii, colours, cameras, settings) goes
through a temporary folder and the PNGs come back the same way.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from cghair_format.camera import Camera
from cghair_format.errors import CghError, MissingDependencyError
from cghair_format.strands import Strands

from .colours import PRESETS

# its own folder: the script folder goes on sys.path, and a module named like one of Blender's
# add-ons (our cycles.py vs the "cycles" add-on) would shadow it
WORKER = Path(__file__).with_name("_bpy_worker") / "render_cycles.py"
SECONDS_PER_VIEW_LIMIT = 600  # a view that takes longer than this is treated as a hang
STARTUP_SECONDS = 120


class CyclesError(CghError, RuntimeError):
    """Blender failed to render; the message carries the end of its output."""


def blender_python() -> str | None:
    """A Python interpreter with bpy (see :func:`cghair_format.exchange.blender.find_blender_python`)."""
    try:
        from cghair_format.exchange.blender import BlenderNotFoundError, find_blender_python
    except ImportError:  # the interchange module predates the finder: only the running interpreter
        return sys.executable if importlib.util.find_spec("bpy") is not None else None
    try:
        return find_blender_python()
    except BlenderNotFoundError:
        return None


def bpy_available() -> bool:
    return blender_python() is not None


def render_cycles(strands: Strands, cameras: list[Camera], *, thickness: float, preset: str = "brown",
                  samples: int = 16, seed: int = 0, progress: bool = False, denoise: bool = False) -> list[np.ndarray]:
    """RGBA images ``[H, W, 4]`` (straight colour, alpha = coverage) of ``strands`` seen by ``cameras``;
    ``denoise`` runs Cycles' OpenImageDenoise on each."""
    python = blender_python()
    if python is None:
        raise MissingDependencyError("bpy", "blender", "rendering with --engine cycles (or run `make blender`)")
    if not cameras:
        return []
    res = {(c.width, c.height) for c in cameras}
    if len(res) != 1:
        raise CyclesError(f"all cameras must have one resolution, got {sorted(res)}")
    width, height = res.pop()
    widths = strands.widths / 2 if strands.widths is not None else None
    radius = widths if widths is not None else np.full(len(strands.points), thickness, np.float32)
    with tempfile.TemporaryDirectory(prefix="cgh_cycles_") as tmp:
        job = Path(tmp)
        arrays = {"points": strands.points.astype(np.float32), "offsets": strands.offsets.astype(np.int64),
                  "radius": np.asarray(radius, np.float32),
                  "c2w": np.stack([c.nerf_matrix() for c in cameras]).astype(np.float64)}
        if strands.colors is not None:
            arrays["colors"] = strands.colors.astype(np.float32)
        np.savez(job / "job.npz", **arrays)
        settings = {"width": width, "height": height, "fov_x": cameras[0].fov_x, "samples": int(samples),
                    "seed": int(seed), "melanin": PRESETS[preset]["melanin"],
                    "redness": PRESETS[preset]["redness"], "up_axis": strands.up_axis, "progress": progress,
                    "denoise": bool(denoise)}
        (job / "job.json").write_text(json.dumps(settings))
        timeout = STARTUP_SECONDS + SECONDS_PER_VIEW_LIMIT * len(cameras)
        try:
            proc = subprocess.run([python, str(WORKER), str(job)], capture_output=True, text=True,
                                  timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            raise CyclesError(f"Blender did not finish {len(cameras)} views within {timeout} s") from exc
        if progress and proc.stderr:
            print(proc.stderr, file=sys.stderr, end="")
        if proc.returncode != 0:
            tail = (proc.stdout + proc.stderr).strip().splitlines()[-15:]
            raise CyclesError(f"Blender exited with code {proc.returncode}:\n" + "\n".join(tail))
        from PIL import Image

        images = []
        for i in range(len(cameras)):
            path = job / f"r_{i:03d}.png"
            if not path.is_file():
                raise CyclesError(f"Blender did not write {path.name}")
            with Image.open(path) as im:
                images.append(np.asarray(im.convert("RGBA"), np.float32) / 255.0)
        return images
