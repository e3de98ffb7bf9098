"""Real captures as training input: the COLMAP and GaussianHaircut layouts, the layout detection
that :func:`training.dataset.read_dataset` uses, and the check that strands and cameras share a frame.

COLMAP layout (as 3D Gaussian Splatting reads it): ``sparse/0/`` (or ``sparse/``) holding
``cameras`` and ``images`` ``.bin`` or ``.txt`` (:mod:`training.colmap`), ``images/`` with the
files the model names, optional ``masks/`` with one hair mask per image.
GaussianHaircut layout: the same sparse model with ``images/`` + ``masks/hair/``, or its
downscaled ``images_2/`` + ``masks_2/hair/`` or ``images_4/`` + ``masks_4/hair/`` (the first pair
present is read); the cameras are scaled to the images' size.

A mask is ``<masks>/<image stem>.png``, ``<masks>/<image name>`` or ``<masks>/<image name>.png``,
a greyscale (or RGB, read as luminance) image of the image's size, 255 = hair. Without masks, an
RGBA image's alpha is the mask, else the whole image counts as hair. Views are sorted by image
name and every 8th (the 8th, 16th, ...) is held out, as :func:`training.dataset.split_indices` does.
Only undistorted pinhole cameras are read (see :mod:`training.colmap`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import colmap
from .dataset import Dataset, DatasetError, View, split_indices

SPARSE_DIRS = ("sparse/0", "sparse")
# (images folder, masks folder or None, layout name), in order of preference
IMAGE_SETS = (("images", "masks/hair", "GaussianHaircut"), ("images_2", "masks_2/hair", "GaussianHaircut"),
              ("images_4", "masks_4/hair", "GaussianHaircut"), ("images", "masks", "COLMAP"),
              ("images", None, "COLMAP"))
MASK_LEVEL = 0.5  # a pixel is hair where its mask is at least this
MIN_INSIDE = 0.5  # refuse training when fewer strand points than this fall inside the masks
CHECK_POINTS = 20_000  # strand points projected by the frame check


@dataclass
class Layout:
    name: str  # "NeRF-synthetic", "COLMAP" or "GaussianHaircut"
    root: Path
    sparse: Path | None = None
    images: Path | None = None
    masks: Path | None = None

    def describe(self) -> str:
        if self.name == "NeRF-synthetic":
            return f"{self.name} layout (transforms_train.json, transforms_test.json)"
        ext = colmap.find_model(self.sparse)[1]
        masks = f"masks {self.masks.relative_to(self.root)}/" if self.masks else "no masks"
        return (f"{self.name} layout (sparse model {self.sparse.relative_to(self.root)}/ .{ext}, "
                f"images {self.images.relative_to(self.root)}/, {masks})")


def detect_layout(root: str | Path) -> Layout:
    """Which layout ``root`` holds, judged by the files present."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"dataset folder {root} does not exist")
    if (root / "transforms_train.json").is_file():
        return Layout("NeRF-synthetic", root)
    sparse = next((root / d for d in SPARSE_DIRS if colmap.find_model(root / d)), None)
    if sparse is None:
        raise DatasetError(f"{root} holds no dataset: expected transforms_train.json (NeRF-synthetic) or a "
                           "COLMAP model in sparse/0/ or sparse/ (cameras and images, .bin or .txt)")
    for images, masks, name in IMAGE_SETS:
        if (root / images).is_dir() and (masks is None or (root / masks).is_dir()):
            return Layout(name, root, sparse, root / images, root / masks if masks else None)
    raise DatasetError(f"{root}: the COLMAP model's images folder images/ (or images_2/, images_4/) is missing")


def read_capture(layout: Layout) -> Dataset:
    """Read a COLMAP or GaussianHaircut capture (see the module docstring)."""
    from PIL import Image

    images = colmap.read_model(layout.sparse)
    views = []
    no_mask = 0
    for im in images:
        path = layout.images / im.name
        if not path.is_file():
            raise DatasetError(f"{path} is missing (image {im.name!r} of the COLMAP model in {layout.sparse})")
        with Image.open(path) as pil:
            has_alpha = "A" in pil.getbands()
            rgba = np.asarray(pil.convert("RGBA"), np.float32) / 255.0
        h, w = rgba.shape[:2]
        camera = _scaled(im.camera, w, h, path)
        if layout.masks is not None:
            rgba[..., 3] = _read_mask(layout.masks, im.name, path, (w, h))
        elif not has_alpha:
            no_mask += 1
        views.append(View(camera, rgba, Path(im.name).stem))
    if no_mask:
        warnings.warn(f"{layout.root}: {no_mask} of {len(views)} images have no hair mask (no masks/ folder, "
                      "no alpha), so the whole image is fitted as hair; add masks/ for a capture with a background",
                      stacklevel=2)
    train, test = split_indices(len(views))
    return Dataset([views[i] for i in train], [views[i] for i in test], {"layout": layout.name})


def _read_mask(folder: Path, name: str, image_path: Path, size: tuple[int, int]) -> np.ndarray:
    from PIL import Image

    stem = Path(name).with_suffix("")
    candidates = (folder / f"{stem}.png", folder / name, folder / f"{name}.png")
    path = next((p for p in candidates if p.is_file()), None)
    if path is None:
        raise DatasetError(f"hair mask of {image_path.name} is missing: expected {candidates[0]}")
    with Image.open(path) as pil:
        if pil.size != size:
            raise DatasetError(f"{path} is {pil.size[0]} x {pil.size[1]} pixels, its image {image_path.name} is "
                               f"{size[0]} x {size[1]}: masks must match their images")
        return np.asarray(pil.convert("L"), np.float32) / 255.0


def _scaled(camera, width: int, height: int, path: Path):
    """``camera`` for an image of ``width`` x ``height``: a downscaled copy (GaussianHaircut's
    images_2, images_4) keeps the model's field of view."""
    if (width, height) == (camera.width, camera.height):
        return camera
    sx, sy = width / camera.width, height / camera.height
    if abs(sx - sy) * max(camera.width, camera.height) > 1.0:  # more than a pixel's rounding apart
        raise DatasetError(f"{path} is {width} x {height} pixels, its COLMAP camera {camera.width} x "
                           f"{camera.height}: not a resized copy of the same view")
    from cghair_format.camera import Camera

    return Camera(width, height, camera.fx * sx, camera.fy * sy, camera.cx * sx, camera.cy * sy,
                  camera.world_to_camera)


def fraction_in_masks(points: np.ndarray, views: list[View], max_points: int = CHECK_POINTS) -> np.ndarray:
    """Per view, the fraction of ``points`` ``[N, 3]`` (an even subsample of at most ``max_points``)
    that project onto hair: in front of the camera, inside the image, on a pixel whose mask (dilated
    by one pixel, for thin strands) is at least :data:`MASK_LEVEL`."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    points = points[:: max(1, len(points) // max_points)]
    out = np.zeros(len(views))
    for k, view in enumerate(views):
        mask = view.image[..., 3] >= MASK_LEVEL
        grown = mask.copy()
        grown[1:] |= mask[:-1]
        grown[:-1] |= mask[1:]
        grown[:, 1:] |= grown[:, :-1].copy()
        grown[:, :-1] |= grown[:, 1:].copy()
        uv, z = view.camera.project(points)
        h, w = mask.shape
        ok = (z > 0) & np.isfinite(uv).all(1)
        ok &= (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        i = np.clip(np.floor(uv[ok, 0]).astype(np.int64), 0, w - 1)
        j = np.clip(np.floor(uv[ok, 1]).astype(np.int64), 0, h - 1)
        out[k] = grown[j, i].sum() / max(len(points), 1)
    return out


def check_strands_in_views(points: np.ndarray, views: list[View], min_inside: float = MIN_INSIDE) -> float:
    """Refuse strands that do not sit where the views see hair (another frame, scale or up axis);
    returns the fraction of strand points inside the masks over all views."""
    per_view = fraction_in_masks(points, views)
    inside = float(per_view.mean()) if len(per_view) else 0.0
    if inside < min_inside:
        worst = int(np.argmin(per_view))
        raise DatasetError(
            f"only {inside:.0%} of the strand points project inside the views' hair masks (view {views[worst].name}: "
            f"{per_view[worst]:.0%}); the strands and cameras are not in the same frame: bring the strands "
            "into the capture's coordinates (scale, up axis, placement) before training")
    return inside
