"""Multi-view datasets in the NeRF-synthetic layout, and rendering them from strands; real captures
(COLMAP, GaussianHaircut) are read by :mod:`training.capture`.

Layout (read and written): ``transforms_train.json`` and ``transforms_test.json``, each with
``camera_angle_x`` and ``frames: [{file_path: "./train/r_000", transform_matrix: 4x4}]``
(OpenGL camera-to-world), images ``train/r_000.png`` as 8-bit RGBA with straight (not
premultiplied) colour; alpha is the hair mask. ``dataset.json`` records how the views were made.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cghair_format.camera import Camera
from cghair_format.errors import CghError
from cghair_format.gaussians import Gaussians, rgb_to_sh0, segment_frames
from cghair_format.strands import Strands

SPLITS = ("train", "test")
ENGINES = ("splat", "cycles")
TEST_EVERY = 8  # every 8th view is held out
FOV_Y_DEG = 40.0
FRAME_MARGIN = 1.15  # the bounding sphere fills the view with this much room
ELEVATION_RANGE = (-15.0, 55.0)
SPLAT_OPACITY = 0.9
SPLAT_SH1_SCALE = 0.15  # strength of the per-strand view-dependent term of the splat ground truth
# root / tip RGB of the melanin presets, for the splat engine; Cycles uses (melanin, redness)
PRESETS: dict[str, dict] = {
    "brown": {"root": (0.20, 0.12, 0.07), "tip": (0.38, 0.25, 0.14), "melanin": 0.6, "redness": 0.4},
    "black": {"root": (0.04, 0.035, 0.03), "tip": (0.09, 0.07, 0.06), "melanin": 0.95, "redness": 0.2},
    "blonde": {"root": (0.55, 0.42, 0.25), "tip": (0.80, 0.66, 0.45), "melanin": 0.2, "redness": 0.3},
    "red": {"root": (0.35, 0.10, 0.04), "tip": (0.60, 0.22, 0.09), "melanin": 0.5, "redness": 0.95},
}


class DatasetError(CghError, ValueError):
    """A dataset folder is missing files or has inconsistent contents."""


@dataclass
class View:
    camera: Camera
    image: np.ndarray  # [H, W, 4] float32 in [0, 1], straight RGB + alpha (mask)
    name: str = ""

    def premultiplied(self, background=(0.0, 0.0, 0.0)) -> np.ndarray:
        """RGB ``[H, W, 3]`` composited over ``background``."""
        a = self.image[..., 3:4]
        return self.image[..., :3] * a + (1 - a) * np.asarray(background, np.float32)


@dataclass
class Dataset:
    train: list[View]
    test: list[View]
    meta: dict = field(default_factory=dict)

    def split(self, name: str) -> list[View]:
        if name not in SPLITS:
            raise DatasetError(f"unknown split {name!r}; choose train or test")
        return self.train if name == "train" else self.test


# --- cameras -----------------------------------------------------------------------------------------


def bounding_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    lo, hi = points.min(0), points.max(0)
    centre = (lo + hi) / 2
    return centre.astype(np.float64), float(np.linalg.norm(points - centre, axis=1).max())


def orbit_cameras(points: np.ndarray, n: int, res: int, up_axis: str = "Y") -> list[Camera]:
    """``n`` cameras on a golden-angle spiral around the points' bounding sphere, all framing it."""
    centre, radius = bounding_sphere(points)
    distance = FRAME_MARGIN * max(radius, 1e-9) / math.sin(math.radians(FOV_Y_DEG) / 2)
    lo, hi = ELEVATION_RANGE
    cams = []
    for i in range(n):
        az = (i * 137.50776405) % 360.0
        el = lo + (hi - lo) * ((i + 0.5) / n)
        cams.append(Camera.orbit(centre, distance, az, el, res, res, up_axis=up_axis, fov_y_deg=FOV_Y_DEG))
    return cams


def split_indices(n: int, test_every: int = TEST_EVERY) -> tuple[list[int], list[int]]:
    test = [i for i in range(n) if i % test_every == test_every - 1] or [n - 1]  # at least one
    return [i for i in range(n) if i not in set(test)], test


# --- reading and writing -----------------------------------------------------------------------------


def _to_u8(image: np.ndarray) -> np.ndarray:
    return (np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)


def write_split(root: str | Path, split: str, views: list[View]) -> None:
    """Write one split's PNGs and ``transforms_<split>.json``."""
    from PIL import Image

    root = Path(root)
    (root / split).mkdir(parents=True, exist_ok=True)
    if not views:
        raise DatasetError(f"no {split} views to write")
    frames = []
    for i, v in enumerate(views):
        name = v.name or f"r_{i:03d}"
        Image.fromarray(_to_u8(v.image), "RGBA").save(root / split / f"{name}.png")
        frames.append({"file_path": f"./{split}/{name}", "transform_matrix": v.camera.nerf_matrix().tolist()})
    cam = views[0].camera
    doc = {"camera_angle_x": cam.fov_x, "w": cam.width, "h": cam.height, "frames": frames}
    (root / f"transforms_{split}.json").write_text(json.dumps(doc, indent=1) + "\n")


def write_dataset(root: str | Path, dataset: Dataset) -> None:
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    for split in SPLITS:
        write_split(root, split, dataset.split(split))
    (root / "dataset.json").write_text(json.dumps(dataset.meta, indent=2) + "\n")


def read_split(root: str | Path, split: str) -> list[View]:
    from PIL import Image

    root = Path(root)
    path = root / f"transforms_{split}.json"
    if not path.is_file():
        raise DatasetError(f"{root} is not a NeRF-synthetic dataset: {path.name} is missing")
    try:
        doc = json.loads(path.read_text())
        angle = float(doc["camera_angle_x"])
        frames = doc["frames"]
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise DatasetError(f"{path}: malformed transforms file ({exc})") from exc
    views = []
    for i, frame in enumerate(frames):
        try:
            rel = str(frame["file_path"])
            matrix = np.asarray(frame["transform_matrix"], np.float64)
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: frame {i} is malformed ({exc})") from exc
        if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
            raise DatasetError(f"{path}: frame {i} transform_matrix must be a finite 4x4 matrix")
        img_path = (root / rel).with_suffix(".png") if not rel.endswith(".png") else root / rel
        if not img_path.is_file():
            raise DatasetError(f"{path}: frame {i} image {img_path} is missing")
        with Image.open(img_path) as im:
            rgba = np.asarray(im.convert("RGBA"), np.float32) / 255.0
        h, w = rgba.shape[:2]
        views.append(View(Camera.from_nerf(matrix, angle, w, h), rgba, img_path.stem))
    if not views:
        raise DatasetError(f"{path}: no frames")
    return views


def read_dataset(root: str | Path) -> Dataset:
    """Read a dataset in any layout :func:`training.capture.detect_layout` knows: NeRF-synthetic
    (both splits; a missing test split is an error, evaluation needs held-out views), COLMAP or
    GaussianHaircut (:mod:`training.capture`)."""
    from .capture import detect_layout, read_capture

    layout = detect_layout(root)
    if layout.name != "NeRF-synthetic":
        return read_capture(layout)
    root = Path(root)
    meta_path = root / "dataset.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    return Dataset(read_split(root, "train"), read_split(root, "test"), meta)


# --- the splat engine's known appearance ------------------------------------------------------------


def strand_segments(strands: Strands) -> tuple[np.ndarray, np.ndarray]:
    """Index of the first point of every segment ``[N_seg]`` and the strand of each segment."""
    owner = np.repeat(np.arange(strands.count), strands.point_counts)
    first = np.flatnonzero(owner[:-1] == owner[1:])
    return first, owner[first]


def strand_colours(strands: Strands, preset: str, seed: int) -> np.ndarray:
    """Per-point RGB ``[N, 3]``: the strands' own colours, else the preset's root-to-tip ramp with a
    per-strand brightness variation."""
    if strands.colors is not None:
        return np.clip(strands.colors.astype(np.float64), 0, 1)
    p = PRESETS[preset]
    counts = strands.point_counts
    owner = np.repeat(np.arange(strands.count), counts)
    start = np.repeat(strands.offsets[:-1], counts)
    t = (np.arange(len(owner)) - start) / np.maximum(np.repeat(counts, counts) - 1, 1)
    rng = np.random.default_rng(seed)
    scale = (1 + 0.25 * rng.standard_normal(strands.count)).clip(0.4, 1.8)[owner]
    rgb = np.asarray(p["root"])[None] * (1 - t[:, None]) + np.asarray(p["tip"])[None] * t[:, None]
    return np.clip(rgb * scale[:, None], 0, 1)


def reference_gaussians(strands: Strands, thickness: float, preset: str = "brown", seed: int = 0,
                        sh_degree: int = 1) -> Gaussians:
    """The splat engine's ground truth: one Gaussian per strand segment (as in the .cgh model), the
    strand colours as band 0 and a random per-strand band-1 term for view dependence."""
    first, owner = strand_segments(strands)
    pts = strands.points.astype(np.float64)
    means, rotations, scales = segment_frames(np.stack([pts[first], pts[first + 1]], 1), thickness)
    colours = strand_colours(strands, preset, seed)
    seg_rgb = (colours[first] + colours[first + 1]) / 2
    sh = np.zeros((len(first), (sh_degree + 1) ** 2, 3), np.float32)
    sh[:, 0] = rgb_to_sh0(seg_rgb)
    if sh_degree >= 1:
        rng = np.random.default_rng(seed + 1)
        sh[:, 1:4] = (SPLAT_SH1_SCALE * rng.standard_normal((strands.count, 3, 3)))[owner]
    return Gaussians(means, rotations, scales, np.full(len(first), SPLAT_OPACITY, np.float32), sh)


def default_thickness(strands: Strands) -> float:
    """The Gaussian radius for strands: the card builder's rule (half the median width, else a
    third of the typical neighbour spacing)."""
    from cghair_format.cards.appearance import default_thickness as rule
    from cghair_format.strands import resample

    res = resample(strands, 16)
    widths = None if res.widths is None else res.widths.reshape(res.count, 16)
    return float(rule(res.points.reshape(res.count, 16, 3).astype(np.float64), widths))


# --- rendering a dataset -----------------------------------------------------------------------------


def render_dataset(strands: Strands, out_dir: str | Path, views: int = 32, res: int = 128,
                   engine: str = "splat", preset: str = "brown", seed: int = 0, samples: int = 16,
                   thickness: float | None = None, progress: bool = False, device: str = "cpu",
                   backend: str | None = None) -> Dataset:
    """Render ``views`` orbit views of ``strands`` at ``res`` x ``res`` and write the dataset.

    ``engine="splat"`` renders the strands' segment Gaussians (fast, known appearance) on the torch
    ``device`` with the rasterizer ``backend`` (:mod:`training.backends`; default: the fastest that runs
    there); ``engine="cycles"`` renders curves with Blender Cycles and the Principled Hair BSDF (needs
    bpy). Every 8th view goes to the test split.
    """
    if engine not in ENGINES:
        raise DatasetError(f"unknown engine {engine!r}; choose {' or '.join(ENGINES)}")
    if preset not in PRESETS:
        raise DatasetError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")
    if views < 2 or res < 8:
        raise DatasetError(f"need at least 2 views of at least 8 x 8 pixels, got {views} at {res}")
    strands.validate()
    if strands.count < 1 or len(strands.points) < 2:
        raise DatasetError("the strands are empty")
    if thickness is None:
        thickness = default_thickness(strands)
    cams = orbit_cameras(strands.points.astype(np.float64), views, res, strands.up_axis)
    if engine == "splat":
        from .backends import render_gaussians, resolve_backend
        from .splatter import torch_device

        device = torch_device(device)
        backend = resolve_backend(backend, device)
        g = reference_gaussians(strands, thickness, preset, seed)
        images = []
        for cam in _progress(cams, progress, "splat"):
            out = render_gaussians(g, cam, device=device, backend=backend)
            a = out["alpha"][..., None]
            straight = np.where(a > 1e-6, out["rgb"] / np.maximum(a, 1e-6), 0.0)
            images.append(np.concatenate([straight, a], -1).astype(np.float32))
    else:
        from .cycles import render_cycles

        images = render_cycles(strands, cams, thickness=thickness, preset=preset, samples=samples,
                               seed=seed, progress=progress)
    train_idx, test_idx = split_indices(views)
    meta = {"engine": engine, "views": views, "res": res, "preset": preset, "seed": seed,
            "thickness": thickness, "strands": strands.count, "samples": samples if engine == "cycles" else None,
            "backend": backend if engine == "splat" else None,
            "up_axis": strands.up_axis}
    ds = Dataset([View(cams[i], images[i], f"r_{i:03d}") for i in train_idx],
                 [View(cams[i], images[i], f"r_{i:03d}") for i in test_idx], meta)
    write_dataset(out_dir, ds)
    return ds


def _progress(items, enabled: bool, desc: str):
    if not enabled:
        return items
    from tqdm import tqdm

    return tqdm(items, desc=desc, unit="view")
