"""Headless renders of an asset: one picture, a NeRF-dataset camera, or a turntable animation.

The API behind ``cgh render``; images are written with pillow (PNG, GIF) or imageio's ffmpeg
plugin (MP4, needs ``imageio-ffmpeg``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cghair_format import HairAsset
from cghair_format.animation import Animation
from cghair_format.atomic import atomic_path
from cghair_format.camera import Camera
from cghair_format.errors import CghError, require

from .camera_control import OrbitController
from .frame import ViewSettings
from .renderer import create_renderer

DEFAULT_SIZE = 800
MAX_SIZE = 16384


class CameraFileError(CghError):
    """A transforms.json camera file is missing fields or malformed."""


@dataclass
class RenderJob:
    width: int | None = None
    height: int | None = None
    azimuth: float = 0.0
    elevation: float = 10.0
    distance: float | None = None
    target: tuple[float, float, float] | None = None
    fov: float = 40.0
    transforms: str | None = None  # NeRF transforms.json
    frame: int = 0
    turntable: int = 0  # frames; 0: one picture
    fps: float = 24.0
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sh_degree: int | None = None
    splat_scale: float = 1.0
    color_by_group: bool = False
    cards: bool = False
    strands: bool = False
    sort: str = "auto"
    rasterizer: str = "auto"
    budget: int | None = None  # Gaussians drawn (level of detail); None: all
    frames: range | None = None  # frames of the animation to render (one camera); None: the rest pose
    turn_sh: bool = True  # with frames: turn each Gaussian's SH with its segment (False: as at rest)

    def settings(self) -> ViewSettings:
        return ViewSettings(sh_degree=self.sh_degree, splat_scale=self.splat_scale,
                            color_by_group=self.color_by_group, show_cards=self.cards,
                            show_strands=self.strands, background=self.background)


def _check_size(name: str, value: int) -> int:
    if not 1 <= int(value) <= MAX_SIZE:
        raise CghError(f"{name} must be between 1 and {MAX_SIZE} pixels, got {value}")
    return int(value)


def nerf_camera(path: str | Path, frame: int = 0, width: int | None = None, height: int | None = None) -> Camera:
    """Camera ``frame`` of a NeRF-synthetic style ``transforms.json`` (``camera_angle_x`` or ``fl_x``)."""
    path = Path(path)
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise CameraFileError(f"{path} is not valid JSON: {exc}") from exc
    frames = meta.get("frames") if isinstance(meta, dict) else None
    if not isinstance(frames, list) or not frames:
        raise CameraFileError(f"{path} has no 'frames' list")
    if not -len(frames) <= frame < len(frames):
        raise CameraFileError(f"{path} has {len(frames)} frames; frame {frame} does not exist")
    entry = frames[frame]
    if not isinstance(entry, dict):
        raise CameraFileError(f"frame {frame} of {path} is not a JSON object")
    try:
        matrix = np.asarray(entry["transform_matrix"], np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise CameraFileError(f"frame {frame} of {path} has no numeric 'transform_matrix'") from exc
    if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
        raise CameraFileError(f"frame {frame} of {path}: transform_matrix must be a finite 4x4 matrix")
    try:
        w = _check_size("width", width if width is not None else entry.get("w") or meta.get("w") or DEFAULT_SIZE)
        h = _check_size("height", height if height is not None else entry.get("h") or meta.get("h") or DEFAULT_SIZE)
    except (TypeError, ValueError) as exc:
        raise CameraFileError(f"{path}: image size 'w'/'h' must be integers: {exc}") from exc
    try:
        if "camera_angle_x" in meta:
            fov_x = float(meta["camera_angle_x"])
        elif "fl_x" in meta:
            fov_x = 2 * math.atan(float(meta.get("w", w)) / (2 * float(meta["fl_x"])))
        else:
            raise CameraFileError(f"{path} gives neither 'camera_angle_x' nor 'fl_x'")
    except (TypeError, ValueError, ZeroDivisionError) as exc:
        raise CameraFileError(f"{path}: the field of view is not a number: {exc}") from exc
    if not 0 < fov_x < math.pi:
        raise CameraFileError(f"{path}: horizontal field of view {fov_x} rad is outside (0, pi)")
    return Camera.from_nerf(matrix, fov_x, w, h)


def job_cameras(job: RenderJob, bounds: tuple[np.ndarray, np.ndarray], up_axis: str) -> list[Camera]:
    """The cameras a job renders: one, or ``turntable`` evenly spaced azimuths."""
    if job.transforms:
        return [nerf_camera(job.transforms, job.frame, job.width, job.height)]
    w = _check_size("width", DEFAULT_SIZE if job.width is None else job.width)
    h = _check_size("height", DEFAULT_SIZE if job.height is None else job.height)
    if not 1.0 <= job.fov <= 170.0:
        raise CghError(f"--fov must be between 1 and 170 degrees, got {job.fov}")
    ctl = OrbitController.framing(*bounds, up_axis=up_axis, fov_y=job.fov)
    if job.target is not None:
        ctl.target = np.asarray(job.target, np.float64)
    if job.distance is not None:
        if not (job.distance > 0 and math.isfinite(job.distance)):
            raise CghError(f"--distance must be a positive number of scene units, got {job.distance}")
        ctl.distance = job.distance
    azimuths = [job.azimuth] if job.turntable == 0 else [job.azimuth + 360.0 * i / job.turntable
                                                           for i in range(job.turntable)]
    return [Camera.orbit(ctl.target, ctl.distance, az, job.elevation, w, h, up_axis, job.fov) for az in azimuths]


def to_uint8(image: np.ndarray) -> np.ndarray:
    """8-bit RGB of a float image in [0, 1] (an 8-bit image is returned as it is)."""
    if image.dtype == np.uint8:
        return image[..., :3]
    return (np.clip(image[..., :3], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def write_images(frames: list[np.ndarray], out: Path, fps: float = 24.0) -> Path:
    """Write one PNG, or an animated GIF/MP4, from float (or 8-bit) ``[H, W, >=3]`` frames."""
    from PIL import Image

    ext = out.suffix.lower()
    if ext not in (".png", ".gif", ".mp4"):
        raise CghError(f"unsupported output {out.name!r}: use .png, .gif or .mp4")
    rgb = [to_uint8(f) for f in frames]
    with atomic_path(out) as tmp:
        if ext == ".png":
            Image.fromarray(rgb[0]).save(tmp)
        elif ext == ".gif":
            images = [Image.fromarray(f) for f in rgb]
            images[0].save(tmp, save_all=True, append_images=images[1:], duration=max(1, round(1000 / fps)), loop=0)
        else:
            require("imageio_ffmpeg", "viewer", "MP4 output", package="imageio-ffmpeg")
            import imageio.v2 as imageio

            # H.264 wants even sizes: pad by one pixel where needed
            h, w = rgb[0].shape[:2]
            padded = [np.pad(f, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge") for f in rgb]
            imageio.mimwrite(tmp, padded, fps=fps, macro_block_size=1)
    return out


def render_job(asset: HairAsset, job: RenderJob, out: str | Path, ctx=None, log=None,
               animation: Animation | None = None) -> Path:
    """Render ``asset`` as ``job`` describes and write ``out``; creates an EGL context if none given.
    ``log`` (e.g. ``print``) is told which OpenGL driver and device render. With ``job.frames``, those
    frames of ``animation`` are rendered from the job's camera, at ``job.fps``; with ``job.turntable`` too,
    the camera goes round in that many images while the clip plays on a loop."""
    from .context import create_headless_context, describe_gl, gl_info

    out = Path(out)
    if job.fps <= 0 or not math.isfinite(job.fps):
        raise CghError(f"--fps must be positive, got {job.fps}")
    if not (job.splat_scale > 0 and math.isfinite(job.splat_scale)):
        raise CghError(f"--splat-scale must be positive, got {job.splat_scale}")
    if job.frames is not None:
        if animation is None:
            raise CghError("--frames renders an animation, and this file holds none: make one with cgh animate "
                           "or name a built-in --motion")
        animation.validate(asset.cards)
    own = ctx is None
    ctx = ctx or create_headless_context()
    ctx.__enter__()  # make it current: another context may have been created since
    if log is not None:
        log(describe_gl(gl_info(ctx)))
    try:
        renderer = create_renderer(ctx, asset, sort=job.sort, rasterizer=job.rasterizer, budget=job.budget,
                                   animated=job.frames is not None, turn_sh=job.turn_sh)
        try:
            cameras = job_cameras(job, renderer.bounds, asset.up_axis)
            settings = job.settings()
            if job.frames is None:
                frames = [to_uint8(renderer.render(cam, settings)) for cam in cameras]
            else:  # with a turntable, image i shows pose frames[i % len] from its camera (the clip loops)
                frames = []
                for i in range(len(cameras) if job.turntable else len(job.frames)):
                    renderer.move_cards(animation.cards(asset.cards, job.frames[i % len(job.frames)]))
                    frames.append(to_uint8(renderer.render(cameras[i % len(cameras)], settings)))
        finally:
            renderer.release()
    finally:
        if own:
            ctx.release()
    return write_images(frames, out, job.fps)
