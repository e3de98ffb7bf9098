"""The dataset types every layout reads into: views (a camera and an RGBA image) in a training, a
validation and a test split.

The test views give the held-out scores that are reported; the validation views are for choosing
settings (an opacity step, a budget, an inset), so that a reported score never rests on the views
its settings were chosen on. Neither is trained on.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from cghair_format.camera import Camera
from cghair_format.errors import CghError

SPLITS = ("train", "val", "test")
EVERY = 8  # of every 8 views (in name order) the 8th is held out for testing and the 4th for validation


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
    val: list[View] = field(default_factory=list)

    def split(self, name: str) -> list[View]:
        """The views of split ``name``. A dataset without validation views (a NeRF-synthetic folder
        with no ``transforms_val.json``, or too few views to spare one) gives its training views for
        ``val``, with a one-line warning: settings are then chosen on the training views, never on
        the test views."""
        if name not in SPLITS:
            raise DatasetError(f"unknown split {name!r}; choose {', '.join(SPLITS)}")
        if name == "val" and not self.val:
            warnings.warn("the dataset has no validation views: using its training views instead "
                          "(re-render it with cgh render-dataset to get val views)", stacklevel=2)
            return self.train
        return {"train": self.train, "val": self.val, "test": self.test}[name]


def split_indices(n: int, every: int = EVERY) -> tuple[list[int], list[int], list[int]]:
    """Train, validation and test indices of ``n`` views: every ``every``-th view (the 8th, 16th, ...)
    is a test view (at least one: the last), every ``every``-th from the ``every // 2``-th (the 4th,
    12th, ...) a validation view, as long as one view is left to train on."""
    test = [i for i in range(n) if i % every == every - 1] or [n - 1]
    val = [i for i in range(n) if i % every == every // 2 - 1 and i not in test]
    if len(val) + len(test) >= n:
        val = []
    held = set(test) | set(val)
    return [i for i in range(n) if i not in held], val, test
