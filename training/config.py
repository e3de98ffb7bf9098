"""Training configuration: one dataclass whose defaults are the paper's values, saved as JSON.

Values the lead's brief attributes to the paper: 30k iterations, K = 10 codebook entries of
dimension D = 64, N_T = 64 card groups, geometry frozen for the first 7k iterations, SH degree 3,
a higher learning rate for the logits. The MLP (one hidden layer of 64, ReLU) follows the lead's
paper-scale stand-in (tests/bench/paper_scale.py). The others (learning rates, loss weights, the
Gumbel temperature schedule) are our choices where the paper is silent, borrowed from 3DGS where
it has an equivalent (D-SSIM weight 0.2, opacity learning rate 0.05).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from cghair_format.errors import CghError
from cghair_format.profiles import DEFAULT_OPACITY_BUDGET, Profile

VARIANTS = ("latents", "unique", "single-sh", "multi-sh", "no-card-clustering")
BACKENDS = ("reference", "native", "gsplat")  # rasterizers, see training/backends.py
CONFIG_VERSION = 1


class ConfigError(CghError, ValueError):
    """A training option is out of range or unknown."""


@dataclass
class TrainConfig:
    variant: str = "latents"
    iterations: int = 30_000
    # model (paper)
    codebook_size: int = 10  # K
    latent_dim: int = 64  # D
    n_groups: int = 64  # N_T card groups (codebooks)
    sh_degree: int = 3
    # model (ours)
    mlp_hidden: list[int] = field(default_factory=lambda: [64])  # as the lead's paper-scale stand-in
    n_cards: int = 800  # when the cards are built here from strands
    points_per_strand: int = 32  # strands resampled to a fixed count P
    card_segments: int = 32
    # optimisation
    geometry_frozen_iters: int = 7_000  # paper
    lr_mlp: float = 1e-3
    lr_codebook: float = 1e-3
    lr_logits: float = 1e-2  # higher than the rest (paper); value ours
    lr_opacity: float = 0.05
    lr_geometry: float = 1e-5  # (u, v) and delta, per unit of card coordinates / scene units
    lr_sh: float = 2.5e-3  # free SH of the unique / single-sh variants (3DGS feature lr)
    lr_final_factor: float = 0.1  # MLP / codebook learning rates decay exponentially to this factor
    tau_start: float = 1.0  # Gumbel-softmax temperature, decays exponentially
    tau_end: float = 0.1
    # losses
    lambda_dssim: float = 0.2
    lambda_alpha: float = 0.1
    lambda_opacity_smooth: float = 0.01
    geometry_rate: float = 0.0  # weight of the strand coder's estimated bits per coordinate while the points move
    # (training.losses.geometry_rate; 0: off, today's geometry training; docs/training.md, "Rate-aware geometry")
    geometry_controls: int = 0  # > 0: each strand moves by a smooth correction, a cubic B-spline of this many
    # coefficients over its points (training.smooth_moves; 0: every point on its own; docs/training.md, "Smooth moves")
    children_follow: bool = True  # the strands the writer stores as blends of others (children) move only with
    # their guides, and the file keeps them so (training.children; docs/training.md, "Children follow their guides")
    # export
    opacity_budget: float = DEFAULT_OPACITY_BUDGET  # share of the training views' blend weight whose Gaussians a
    # quantized file may store less opaque, down to 0 (training/visibility.py; 0: every opacity within the bound)
    # bookkeeping
    seed: int = 0
    checkpoint_every: int = 1_000
    log_every: int = 50
    background: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def validate(self) -> TrainConfig:
        if self.variant not in VARIANTS:
            raise ConfigError(f"unknown variant {self.variant!r}; choose one of {', '.join(VARIANTS)}")
        for name in ("iterations", "codebook_size", "latent_dim", "n_groups", "n_cards",
                     "points_per_strand", "card_segments", "checkpoint_every", "log_every"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < (0 if name == "iterations" else 1):
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if self.points_per_strand < 4:
            raise ConfigError(f"points_per_strand must be >= 4, got {self.points_per_strand}")
        if self.codebook_size > 256:
            raise ConfigError(f"codebook_size must be <= 256 (format limit), got {self.codebook_size}")
        if self.sh_degree not in (0, 1, 2, 3):
            raise ConfigError(f"sh_degree must be 0..3, got {self.sh_degree}")
        if not 0 < self.tau_end <= self.tau_start:
            raise ConfigError("need 0 < tau_end <= tau_start")
        if not (isinstance(self.geometry_rate, (int, float)) and 0 <= self.geometry_rate < float("inf")):
            raise ConfigError(f"geometry_rate must be a number >= 0, got {self.geometry_rate!r}")
        if not isinstance(self.geometry_controls, int) or isinstance(self.geometry_controls, bool) \
                or self.geometry_controls < 0:
            raise ConfigError(f"geometry_controls must be an integer >= 0, got {self.geometry_controls!r}")
        if not isinstance(self.children_follow, bool):
            raise ConfigError(f"children_follow must be true or false, got {self.children_follow!r}")
        if not 0 <= self.opacity_budget < 1:
            raise ConfigError(f"opacity_budget must be in [0, 1), got {self.opacity_budget}")
        if len(self.background) != 3:
            raise ConfigError("background must have 3 values")
        return self

    def to_dict(self) -> dict:
        return {"version": CONFIG_VERSION, **dataclasses.asdict(self)}

    @classmethod
    def from_dict(cls, data: dict) -> TrainConfig:
        data = dict(data)
        data.pop("version", None)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown config keys: {', '.join(unknown)}")
        return cls(**data).validate()

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> TrainConfig:
        try:
            return cls.from_dict(json.loads(Path(path).read_text()))
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{path}: not valid JSON ({exc})") from exc


@dataclass
class RunOptions:
    """How one training run is carried out, beside what it trains (:class:`TrainConfig`): where it
    writes, what it resumes, where it runs. :func:`training.train.train`'s keyword arguments."""

    out: Path | None = None  # the .cgh (and <out>.train.json) to write; None: write nothing
    checkpoint: Path | None = None  # default <out>.ckpt.pt
    resume: Path | None = None  # a checkpoint to continue
    profile: str | Profile = "compact"  # precision of the written .cgh (a name, or a Profile)
    progress: bool = True  # a progress bar on ``log``
    log: TextIO = field(default_factory=lambda: sys.stderr)
    threads: int | None = None  # torch CPU threads (None: torch's choice)
    stop_at: int | None = None  # end after this iteration as if interrupted (checkpoint, no export)
    device: str = "cpu"  # torch device
    backend: str | None = None  # rasterizer (training.backends; None: the fastest that runs on device)

    def checkpoint_path(self) -> Path | None:
        if self.checkpoint:
            return Path(self.checkpoint)
        return Path(self.out).with_suffix(".ckpt.pt") if self.out is not None else None
