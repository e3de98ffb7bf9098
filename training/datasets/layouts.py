"""The dataset layouts, told apart by the files present: NeRF-synthetic (:mod:`.nerf`), COLMAP and
GaussianHaircut (:mod:`.capture`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import colmap
from .types import DatasetError

SPARSE_DIRS = ("sparse/0", "sparse")
# (images folder, masks folder or None, layout name), in order of preference
IMAGE_SETS = (("images", "masks/hair", "GaussianHaircut"), ("images_2", "masks_2/hair", "GaussianHaircut"),
              ("images_4", "masks_4/hair", "GaussianHaircut"), ("images", "masks", "COLMAP"),
              ("images", None, "COLMAP"))


@dataclass
class Layout:
    name: str  # "NeRF-synthetic", "COLMAP" or "GaussianHaircut"
    root: Path
    sparse: Path | None = None
    images: Path | None = None
    masks: Path | None = None

    def describe(self) -> str:
        if self.name == "NeRF-synthetic":
            val = ", transforms_val.json" if (self.root / "transforms_val.json").is_file() else ", no val views"
            return f"{self.name} layout (transforms_train.json, transforms_test.json{val})"
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
