"""The NeRF-synthetic layout, read and written.

``transforms_train.json``, ``transforms_test.json`` and, optionally, ``transforms_val.json`` (the
validation views), each with ``camera_angle_x`` and
``frames: [{file_path: "./train/r_000", transform_matrix: 4x4}]`` (OpenGL camera-to-world), images
``train/r_000.png`` as 8-bit RGBA with straight (not premultiplied) colour; alpha is the hair mask.
``dataset.json`` records how the views were made.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cghair_format.atomic import atomic_path, write_text
from cghair_format.camera import Camera

from .types import SPLITS, Dataset, DatasetError, View


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
        with atomic_path(root / split / f"{name}.png") as tmp:
            Image.fromarray(_to_u8(v.image), "RGBA").save(tmp)
        frames.append({"file_path": f"./{split}/{name}", "transform_matrix": v.camera.nerf_matrix().tolist()})
    cam = views[0].camera
    doc = {"camera_angle_x": cam.fov_x, "w": cam.width, "h": cam.height, "frames": frames}
    write_text(root / f"transforms_{split}.json", json.dumps(doc, indent=1) + "\n")


def write_dataset(root: str | Path, dataset: Dataset) -> None:
    """Every split (the validation split only where it has views) and ``dataset.json``."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    for split in SPLITS:
        views = getattr(dataset, split)
        if split != "val" or views:
            write_split(root, split, views)
        elif (root / "transforms_val.json").is_file():  # left by an earlier dataset in this folder
            (root / "transforms_val.json").unlink()
    write_text(root / "dataset.json", json.dumps(dataset.meta, indent=2) + "\n")


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


def read_nerf(root: str | Path) -> Dataset:
    """Every split (a missing test split is an error: evaluation needs held-out views; a missing
    validation split is not, see :meth:`.types.Dataset.split`) and ``dataset.json``."""
    root = Path(root)
    meta_path = root / "dataset.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    test = read_split(root, "test")
    val = read_split(root, "val") if (root / "transforms_val.json").is_file() else []
    test_poses = {v.camera.world_to_camera.tobytes() for v in test}
    shared = [v.name for v in val if v.camera.world_to_camera.tobytes() in test_poses]
    if shared:
        raise DatasetError(f"{root}: {len(shared)} validation views (first {shared[0]}) have the pose of a test view: "
                           "choosing settings on test views would flatter the reported scores; give "
                           "transforms_val.json other views, or remove it")
    return Dataset(read_split(root, "train"), test, meta, val)
