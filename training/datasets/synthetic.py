"""Datasets rendered from strands: the splat engine (the strands' segment Gaussians with a known
appearance) or Blender Cycles (:mod:`.cycles`), from an orbit of cameras (:mod:`.cameras`), written
in the NeRF-synthetic layout (:mod:`.nerf`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from cghair_format.gaussians import Gaussians, rgb_to_sh0, segment_frames
from cghair_format.strands import Strands

from .cameras import orbit_cameras
from .colours import PRESETS, multitone_colours, strand_colours
from .nerf import write_dataset
from .types import Dataset, DatasetError, View, split_indices

ENGINES = ("splat", "cycles")
SPLAT_OPACITY = 0.9
SPLAT_SH1_SCALE = 0.15  # strength of the per-strand view-dependent term of the splat ground truth


def strand_segments(strands: Strands) -> tuple[np.ndarray, np.ndarray]:
    """Index of the first point of every segment ``[N_seg]`` and the strand of each segment."""
    owner = np.repeat(np.arange(strands.count), strands.point_counts)
    first = np.flatnonzero(owner[:-1] == owner[1:])
    return first, owner[first]


def prepare_strands(strands: Strands, points: int | None = None, count: int | None = None,
                    seed: int = 0) -> Strands:
    """The strands resampled (cubic B-spline) to ``points`` points each, then densified (or
    subsampled) to ``count`` strands: the paper's 100 points x 25,000 strands from a real model."""
    from cghair_format.strands import densify, resample

    if points is not None:
        strands = resample(strands, points, method="bspline")
    if count is not None:
        strands = densify(strands, count, seed=seed)
    return strands


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


def render_dataset(strands: Strands, out_dir: str | Path, views: int = 32, res: int = 128,
                   engine: str = "splat", preset: str = "brown", seed: int = 0, samples: int = 16,
                   thickness: float | None = None, progress: bool = False, device: str = "cpu",
                   multitone: int = 0, denoise: bool = False, backend: str | None = None) -> Dataset:
    """Render ``views`` orbit views of ``strands`` at ``res`` x ``res`` and write the dataset.

    ``engine="splat"`` renders the strands' segment Gaussians (fast, known appearance) on the torch
    ``device`` with the rasterizer ``backend`` (:mod:`training.backends`; default: the fastest that runs
    there); ``engine="cycles"`` renders curves with Blender Cycles and the Principled Hair BSDF (needs
    bpy), ``denoise`` with its OpenImageDenoise pass. ``multitone`` > 0 colours every strand in that many
    segments (:func:`multitone_colours`) instead of its own colours or the preset. Every 8th view goes to
    the test split and every 8th from the 4th to the validation split (:func:`.types.split_indices`).
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
    if multitone:
        strands = replace(strands, colors=multitone_colours(strands, multitone, seed).astype(np.float32))
    cams = orbit_cameras(strands.points.astype(np.float64), views, res, strands.up_axis)
    if engine == "splat":
        from ..backends import render_gaussians, resolve_backend
        from ..splatter import torch_device

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
                               seed=seed, progress=progress, denoise=denoise)
    train_idx, val_idx, test_idx = split_indices(views)
    meta = {"engine": engine, "views": views, "res": res, "preset": preset, "seed": seed,
            "thickness": thickness, "strands": strands.count, "samples": samples if engine == "cycles" else None,
            "up_axis": strands.up_axis, "points": int(strands.point_counts.max()), "multitone": multitone,
            "denoise": denoise if engine == "cycles" else None, "backend": backend if engine == "splat" else None}
    def views_at(indices: list[int]) -> list[View]:
        return [View(cams[i], images[i], f"r_{i:03d}") for i in indices]

    ds = Dataset(views_at(train_idx), views_at(test_idx), meta, views_at(val_idx))
    write_dataset(out_dir, ds)
    return ds


def _progress(items, enabled: bool, desc: str):
    if not enabled:
        return items
    from tqdm import tqdm

    return tqdm(items, desc=desc, unit="view")
