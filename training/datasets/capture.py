"""Real captures as training input: the COLMAP and GaussianHaircut layouts (:mod:`.layouts` tells
them apart).

COLMAP layout (as 3D Gaussian Splatting reads it): ``sparse/0/`` (or ``sparse/``) holding
``cameras`` and ``images`` ``.bin`` or ``.txt`` (:mod:`.colmap`), ``images/`` with the
files the model names, optional ``masks/`` with one hair mask per image.
GaussianHaircut layout: the same sparse model with ``images/`` + ``masks/hair/``, or its
downscaled ``images_2/`` + ``masks_2/hair/`` or ``images_4/`` + ``masks_4/hair/`` (the first pair
present is read); the cameras are scaled to the images' size.

A mask is ``<masks>/<image stem>.png``, ``<masks>/<image name>`` or ``<masks>/<image name>.png``,
a greyscale (or RGB, read as luminance) image of the image's size, 255 = hair. Without masks, an
RGBA image's alpha is the mask, else the whole image counts as hair. Views are sorted by image
name; every 8th (the 8th, 16th, ...) is held out for testing and every 8th from the 4th (the 4th,
12th, ...) for validation, as :func:`.types.split_indices` does.
Only undistorted pinhole cameras are read (see :mod:`.colmap`).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from . import colmap
from .layouts import Layout
from .types import Dataset, DatasetError, View, split_indices


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
    train, val, test = split_indices(len(views))
    return Dataset([views[i] for i in train], [views[i] for i in test], {"layout": layout.name},
                   [views[i] for i in val])


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
