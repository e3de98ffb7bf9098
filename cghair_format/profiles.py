"""Precision profiles: how the writer quantizes each part of an asset (spec: "Profiles").

Each profile states its error bounds; the writer enforces the position bound by measuring the
decoded points and tightening the step until it holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

# the loosest point tolerance ``Profile.with_position_tolerance`` takes: 1 % of the diagonal (about 4 mm on a
# 40 cm groom), 50 x compact's
MAX_POSITION_TOLERANCE = 0.01
# the finest opacity step ``Profile.for_opacities`` takes: 1/255
MAX_ADAPTIVE_OPACITY_SCALE = 127.5


@dataclass(frozen=True)
class Profile:
    name: str
    lossless: bool = False
    position_tolerance: float = 2e-4  # max point error / bounding-box diagonal
    # opacity = round(o * scale) / scale: max error 0.5 / scale (compact: 1/15, chosen of 1/7 ... 1/63 on one small
    # model's validation views, 0.02 dB there and 0.05 dB on another model's test views against 1/63, 40 % fewer
    # opacity bytes; docs/ablation.md, "Validation"; on four trained files 0.01-0.07 dB, "The trained file")
    opacity_scale: float = 7.5
    # where the opacities are low (thin, translucent hair), the writer halves the opacity step (within 1/31,
    # 1/63, ... 1/255) until the mean rounding error is at most this share of the mean opacity (None: never). 0.08 keeps
    # 1/15 on the paper-scale files (0.05-0.06 there, 0.05-0.07 dB held out) and takes 1/63 on a small groom
    # trained 10,000 iterations whose median opacity is 0.02 (1/15: 0.21 and 0.82 dB on its validation views;
    # 1/31: 0.12 and 0.17 dB; 1/63: 0.07 and 0.02 dB; docs/ablation.md, "Opacity steps for translucent hair")
    opacity_error: float | None = None
    logit_levels: int = 63  # soft logits stored as round(levels * exp((logit - max) / temperature)) ...
    logit_floor: float = -16.0  # ... and a stored 0 decodes to this logit
    # codebook and MLP weights (and biases): integers times a step of this fraction of each array's RMS
    # (0.35: the error of the 4-bit levels per row it replaced)
    weight_step: float = 0.35
    # the MLP layers' fraction, where it differs (None: weight_step). The MLP is a fixed cost whatever the
    # strand count; compact 0.7 was chosen of 0.35 ... 1.4 on two small models' validation views (0.03 dB,
    # MLPW 26-27 % smaller) and costs 0.04-0.13 dB on their test views (docs/compression.md, "MLP weights of
    # small files")
    mlp_step: float | None = None
    normal_bits: int = 8  # card normals: angles about the spine in 2^bits steps a turn (8..24), error pi / 2^bits rad
    # hierarchical predictor: coarse samples every this many points, the one of these that codes the
    # strand points of a sample of cards smaller (the first codes the cards while the writer chooses)
    base_strides: tuple[int, ...] = (16, 8)
    zstd_level: int = 19
    description: str = ""

    def __post_init__(self) -> None:
        """A profile the writer can follow and whose files the reader accepts (META's ranges, spec 3)."""
        problems = [what for what, ok in (
            ("position_tolerance must be a positive number", 0 < self.position_tolerance < 1),
            ("opacity_scale must be a positive number", 0 < self.opacity_scale < math.inf),
            ("opacity_error must be None or a positive number",
             self.opacity_error is None or 0 < self.opacity_error < math.inf),
            ("logit_levels must be in [1, 2^24]", 1 <= self.logit_levels <= 1 << 24),
            ("logit_floor must be in [-1e6, 0]", -1e6 <= self.logit_floor <= 0),
            ("weight_step must be a positive number", 0 < self.weight_step < math.inf),
            ("mlp_step must be None or a positive number", self.mlp_step is None or 0 < self.mlp_step < math.inf),
            ("normal_bits must be in [8, 24]", 8 <= self.normal_bits <= 24),
            ("base_strides must list powers of two in [2, 256]",
             len(self.base_strides) > 0 and all(2 <= b <= 256 and not b & (b - 1) for b in self.base_strides)),
            ("zstd_level must be in [1, 22]", 1 <= self.zstd_level <= 22)) if not ok]
        if problems:
            raise ValueError(f"profile {self.name!r}: " + "; ".join(problems))

    def with_position_tolerance(self, fraction: float | None) -> Profile:
        """This profile with its strand points held within ``fraction`` of the bounding-box diagonal instead
        (None: as it is); a file so written records the bound in META (``quant.position_tolerance``)."""
        if fraction is None:
            return self
        if self.lossless:
            raise ValueError(f"profile {self.name!r} stores points exactly: a point tolerance needs a quantized "
                             "profile (compact or high)")
        if not 0 < fraction <= MAX_POSITION_TOLERANCE:
            raise ValueError(f"a point tolerance is a fraction of the bounding-box diagonal in (0, "
                             f"{MAX_POSITION_TOLERANCE:g}], got {fraction}")
        return replace(self, position_tolerance=float(fraction))

    @property
    def states_tolerance(self) -> bool:
        """Whether a file of this profile records its point bound: a quantized profile that is not one of
        :data:`PROFILES` as it stands (its name alone does not tell the bound)."""
        return not self.lossless and (self.name not in PROFILES or
                                      PROFILES[self.name].position_tolerance != self.position_tolerance)

    def for_opacities(self, opacity: np.ndarray) -> Profile:
        """This profile with the opacity step the writer takes for ``opacity`` (the asset's real segments'):
        its own, or, where the mean rounding error would exceed ``opacity_error`` of the mean opacity, the
        coarsest of the finer steps (within 1/31, 1/63, ... 1/255) that keeps within it, else the finest. A
        file records its step (META ``quant.opacity_scale``), so a decoder needs nothing of this."""
        if self.lossless or self.opacity_error is None:
            return self
        o = np.asarray(opacity, dtype=np.float64).ravel()  # (a validated asset's: in [0, 1])
        limit = self.opacity_error * (float(o.mean()) if o.size else 0.0)
        scale = self.opacity_scale
        while scale < MAX_ADAPTIVE_OPACITY_SCALE and limit > 0 and _mean_error(o, scale) > limit:
            scale = 2 * scale + 0.5  # 1/15 -> 1/31 -> 1/63: half the step, 0 and 1 still on it
        return self if scale == self.opacity_scale else replace(self, opacity_scale=scale)

    @property
    def opacity_tolerance(self) -> float:
        return 0.5 / self.opacity_scale

    @property
    def mlp_fraction(self) -> float:
        """The MLP layers' step, as a fraction of each layer's RMS."""
        return self.weight_step if self.mlp_step is None else self.mlp_step


PROFILES: dict[str, Profile] = {
    "lossless": Profile("lossless", lossless=True, zstd_level=9,
                        description="every float32 value stored exactly (byte-shuffled + zstd)"),
    "high": Profile("high", position_tolerance=2e-5, opacity_scale=1023.5, logit_levels=8191,
                    logit_floor=-24.0, weight_step=0.02, normal_bits=12,
                    description="points within 2e-5 of the bbox diagonal, opacity within 1/2047"),
    "compact": Profile("compact", mlp_step=0.7, opacity_error=0.08,
                       description="the default: points within 2e-4 of the bbox diagonal, opacity within 1/15 "
                                   "(finer where the opacities are low), "
                                   "codebooks on steps of 0.35 RMS, MLP weights 0.7 RMS"),
}
DEFAULT_PROFILE = "compact"
# what a trained file's quantized opacities may give up: the Gaussians that together carry this share of the
# training views' blend weight may be stored less opaque (training/visibility.py). 0.1 was chosen of 0 ... 0.3
# on one small model's validation views (0.01 dB there) and costs 0.10 dB on another's test views (with 1/15:
# 0.15 dB for 62 % off OPAC); on the paper-scale model 42-48 % off OPAC for 0.01-0.05 dB held out
# (docs/ablation.md, "Validation" and "Negligible opacities")
DEFAULT_OPACITY_BUDGET = 0.1


def _mean_error(opacity: np.ndarray, scale: float) -> float:
    """The mean error of ``opacity`` stored as round(o * scale) / scale."""
    return float(np.abs(np.round(opacity * scale) / scale - opacity).mean())


def get_profile(name: str | Profile) -> Profile:
    if isinstance(name, Profile):
        return name
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown profile {name!r}; choose one of {', '.join(PROFILES)}") from None
