"""The dataset types every layout reads into: views (a camera and an RGBA image) in a training and a
test split."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cghair_format.camera import Camera
from cghair_format.errors import CghError

SPLITS = ("train", "test")
TEST_EVERY = 8  # every 8th view is held out


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


def split_indices(n: int, test_every: int = TEST_EVERY) -> tuple[list[int], list[int]]:
    test = [i for i in range(n) if i % test_every == test_every - 1] or [n - 1]  # at least one
    return [i for i in range(n) if i not in set(test)], test
