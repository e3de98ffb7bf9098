"""What changes from one training iteration to the next: the view, the learning rates, the geometry
freeze and the Gumbel-softmax temperature, in one object that the training step asks once per iteration."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .config import TrainConfig
from .model import HairModel, tau_at


@dataclass(frozen=True)
class Iteration:
    view: int  # index among the training views
    tau: float  # Gumbel-softmax temperature
    geometry_on: bool  # the strand points move


def view_at(seed: int, iteration: int, n_views: int) -> int:
    """The training view of an iteration: a fresh permutation of the views every epoch, derived
    from the seed and the epoch alone so that a resumed run sees the same views."""
    epoch, index = divmod(iteration, n_views)
    return int(np.random.default_rng([seed, epoch]).permutation(n_views)[index])


class Schedule:
    """Sets the model and the optimiser up for each iteration. The appearance groups'
    (:data:`HairModel.DECAYING_GROUPS`) learning rates decay exponentially to ``lr_final_factor`` of
    their initial value over the run; the geometry groups' (:data:`HairModel.GEOMETRY_GROUPS`) are 0, and
    the points do not train, for the first ``geometry_frozen_iters``; the others stay as they start."""

    def __init__(self, config: TrainConfig, model: HairModel, optimizer: torch.optim.Optimizer, n_views: int):
        self.config, self.model, self.optimizer, self.n_views = config, model, optimizer, n_views
        # the initial rates, read before a checkpoint's (already decayed) rates are loaded
        self.base_lr = [g["lr"] for g in optimizer.param_groups]
        self.decays = [g["name"] in HairModel.DECAYING_GROUPS for g in optimizer.param_groups]
        self.geometry = [g["name"] in HairModel.GEOMETRY_GROUPS for g in optimizer.param_groups]

    def lr_factor(self, iteration: int) -> float:
        frac = min(1.0, iteration / max(1, self.config.iterations))
        return self.config.lr_final_factor ** frac

    def apply(self, iteration: int) -> Iteration:
        """Set the learning rates and the geometry freeze of ``iteration``; returns its view and temperature."""
        geometry_on = iteration >= self.config.geometry_frozen_iters
        self.model.set_geometry_trainable(geometry_on)
        factor = self.lr_factor(iteration)
        for g, base, decays, geometry in zip(self.optimizer.param_groups, self.base_lr, self.decays, self.geometry,
                                             strict=True):
            g["lr"] = 0.0 if geometry and not geometry_on else base * (factor if decays else 1.0)
        return Iteration(view_at(self.config.seed, iteration, self.n_views),
                         tau_at(self.config, iteration), geometry_on)
