"""The writer's per-file choices for the strand points (spec 4.3 leaves them to the writer): each one
codes a sample of the file's strands every way it allows and keeps the smallest.

They are made once, on the first step the writer tries, and kept for the others (they hardly depend on
the step); META records them, so that a reader needs none of this (docs/compression.md, "The writer's
per-file choices").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .. import rans
from ..asset import HairAsset
from ..geometry import CardMap, card_scales
from ..parallel import map_threads
from ..profiles import Profile
from ..quantize import level_plan
from ..residual_coder import coded_bytes
from ..strand_coder import (
    NEWTON_STEPS,
    DeadZone,
    Prediction,
    base_residuals,
    encode_uvd,
    neighbour_encode,
    neighbour_order,
)
from .chunks import with_neighbour_prediction
from .layout import uvd_scale

BASE_SAMPLE_CARDS = 100  # the base stride and guide are chosen on this many cards


@dataclass(frozen=True)
class Choices:
    """The choices for a file's strand points (META ``quant``), and the dead zone's (the writer's own)."""

    base_stride: int
    base_order: tuple[int, int, int]
    newton_steps: int
    neighbour_zone: bool
    level_taps: tuple[int, ...]
    base_guide: int
    level_guide: bool


def choose(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray, q: dict, zone: DeadZone,
           guide: int) -> Choices:
    """Every choice after the base samples' (``q["base_stride"]``, ``guide``: :func:`choose_base_samples`,
    made on the input's cards) for the strands ``y`` (``[S, P, 3]`` steps on the quantized cards of
    ``cmap``), in turn, each on the plan the ones before it settled."""
    stride = q["base_stride"]
    base_order = choose_base_order(strand_card, y, stride)
    plan = Prediction(stride, base_order, NEWTON_STEPS, newton_halvings=q["newton_halvings"],
                      stretch_max=q["stretch_max"], base_guide=guide)
    plan = replace(plan, newton_steps=choose_newton_steps(cmap, strand_card, y, scale, plan))
    neighbour_zone = choose_neighbour_zone(cmap, strand_card, y, scale, plan, zone)
    zone = zone._replace(neighbour=neighbour_zone)
    plan = replace(plan, level_taps=choose_level_taps(cmap, strand_card, y, scale, plan, zone))
    return Choices(stride, base_order, plan.newton_steps, neighbour_zone, plan.level_taps, guide,
                   choose_level_guide(cmap, strand_card, y, scale, plan, zone))


def normal_bits(asset: HairAsset, prof: Profile) -> int:
    """The profile's bits for the card normals' angles, or more where points lie so far off their card
    that the normals' error (at most pi / 2^bits rad, bounded here by 4 / 2^bits, times the distance)
    would reach a quarter of the shortest card segment: a step in ``u`` would then move such a point
    far more than the strip does, and no step would meet the tolerance."""
    seg = np.linalg.norm(np.diff(asset.cards.spine.astype(np.float64), axis=1), axis=-1).min(axis=1)
    far = np.zeros(asset.cards.count)
    np.maximum.at(far, asset.strand_card, np.abs(asset.uvd[..., 2]).max(axis=1))
    need = float(np.max(8 * far / np.maximum(seg, 1e-30), initial=0.0))
    return int(np.clip(math.ceil(math.log2(max(need, 1.0))) + 1, prof.normal_bits, 24))


def choose_base_samples(asset: HairAsset, q: dict, zone: DeadZone, strides: tuple[int, ...]) -> tuple[int, int]:
    """The base stride (spec 4.1, 4.3) of ``strides`` (the profile's: 16 or 8) and the base samples'
    guide (0: none, 2: the card neighbour's steps scaled as the strands' previous steps compare, 3: the
    steps of the most alike earlier strand): of both guides at each stride and none at the first,
    whichever codes the strands of a sample of cards smallest (4-point interpolation, the dead zone
    trying the neighbour's residual; on the input's cards, before they are quantized at the stride
    chosen). Wavy strands want base samples closer together, straighter ones fewer, and straight
    strands of unequal lengths the scaled guide. The sample is coded with the neighbour's residual in
    the dead zone, as the file is: without it the sample can rank the strides the wrong way round
    (docs/compression.md, "The writer's per-file choices")."""
    cmap = CardMap(asset.cards)
    scale = uvd_scale(*card_scales(asset.cards, q["step"]), asset.strand_card, q["step"])
    y = asset.uvd * scale[:, None, :]
    orders = dict(zip(strides, map_threads(lambda stride: choose_base_order(asset.strand_card, y, stride),
                                           list(strides)), strict=True))
    tried = [(stride, guide) for stride in strides for guide in (2, 3)] + [(strides[0], 0)]

    def size(trial: tuple[int, int]) -> float:
        stride, guide = trial
        plan = Prediction(stride, orders[stride], NEWTON_STEPS, newton_halvings=q["newton_halvings"],
                          stretch_max=q["stretch_max"], base_guide=guide)
        return coded_bytes(sample_residuals(cmap, asset.strand_card, y, scale, plan, zone._replace(neighbour=True),
                                            BASE_SAMPLE_CARDS))

    sizes = dict(zip(tried, map_threads(size, tried), strict=True))
    return min(sizes, key=sizes.get)


def choose_base_order(strand_card: np.ndarray, y: np.ndarray, base_stride: int) -> tuple[int, int, int]:
    """Per channel (u, v, delta), the base samples' predictor, linear extrapolation (2) or the previous
    sample (1), whichever the coder's estimate finds smaller once neighbour prediction has had its
    say: strands of a card that run parallel share their steps more than their bends, which favours
    1; a strand advancing along its card at an even pace favours 2 for u."""
    base, _ = level_plan(y.shape[1], base_stride)
    order, starts = neighbour_order(strand_card)
    sizes = {}
    for k in (2, 1):
        r = base_residuals(y, base, (k, k, k))[:, 1:]
        sizes[k] = [min(rans.estimate_bytes(r[..., ch]),
                        rans.estimate_bytes(neighbour_encode(r[..., ch], order, starts))) for ch in range(3)]
    return tuple(1 if sizes[1][ch] < sizes[2][ch] else 2 for ch in range(3))


def choose_newton_steps(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                        plan: Prediction, sample: int = 512) -> int:
    """World-guided prediction (``plan.newton_steps``) or plain card-space prediction (0), whichever
    codes an evenly spaced sample of strands smaller. Strands smooth in the world (real hair) favour
    the former; strands smooth on their card (procedural examples) the latter."""
    pick = np.linspace(0, len(strand_card) - 1, min(sample, len(strand_card))).astype(np.int64)
    sizes = {}
    for steps in (plan.newton_steps, 0):
        trial = replace(plan, newton_steps=steps)
        base, levels, *_ = encode_uvd(cmap, strand_card[pick], y[pick], scale[pick], trial)
        sizes[steps] = sum(rans.estimate_bytes(r) for r in [base] + levels)
    return min(sizes, key=sizes.get)


def choose_neighbour_zone(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                          plan: Prediction, zone: DeadZone) -> bool:
    """Whether the dead zone first tries the card neighbour's residual: whichever codes the strands of
    a sample of cards smaller. It pays where a card's strands are much alike (strands densified from
    fewer) and costs a little where they are not (docs/compression.md, "Dead zone")."""
    tried = [True, False]
    sizes = map_threads(lambda neighbour: sum(map(rans.estimate_bytes, sample_residuals(
        cmap, strand_card, y, scale, plan, zone._replace(neighbour=neighbour), 64))), tried)
    return tried[int(np.argmin(sizes))]


def choose_level_taps(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                      plan: Prediction, zone: DeadZone) -> tuple[int, ...]:
    """Per refinement level, the interpolation width (2, 4 or 6; the format allows 8 too, which did
    not beat 6 on real hair) whose residuals the estimate finds smallest on the strands of a sample
    of cards, each width tried on every level at once; kept if the strand coder then codes that
    sample smaller than with 4 everywhere. Wavy strands want wide interpolation at the middle levels;
    the coarsest level, whose neighbours lie B points apart, is often best linear. The widths
    interact (the dead zone leaves a coarser level's reconstruction on its prediction, from which
    the finer levels predict) and the estimate ignores the coder's contexts, so close calls can come
    out the other way: hence the check (docs/compression.md, "The writer's per-file choices")."""
    levels = len(level_plan(y.shape[1], plan.base_stride)[1])
    widths = (2, 4, 6)
    trial = dict(zip(widths, map_threads(lambda t: sample_residuals(
        cmap, strand_card, y, scale, replace(plan, level_taps=(t,) * levels), zone), list(widths)), strict=True))
    chosen = tuple(widths[k] for k in np.argmin([list(map(rans.estimate_bytes, trial[t][1:])) for t in widths],
                                                axis=0))
    if chosen == (4,) * levels:
        return chosen
    mixed = sample_residuals(cmap, strand_card, y, scale, replace(plan, level_taps=chosen), zone)
    return chosen if coded_bytes(mixed) < coded_bytes(trial[4]) else (4,) * levels


def choose_level_guide(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                       plan: Prediction, zone: DeadZone) -> bool:
    """Whether each base segment's refinement residuals are stored as differences from those of the
    most alike strand before it on the card (spec 4.3, ``level_guide``) rather than the card
    neighbour's: whichever codes the strands of a sample of cards smaller. Wavy strands densified from
    fewer gain most, real strands a little, and some models lose (docs/compression.md, "The most alike
    strand")."""
    unguided, guided = map_threads(lambda g: coded_bytes(sample_residuals(
        cmap, strand_card, y, scale, replace(plan, level_guide=g), zone, BASE_SAMPLE_CARDS)), [False, True])
    return guided < unguided


def sample_residuals(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray, plan: Prediction,
                     zone: DeadZone, cards: int = 200) -> list[np.ndarray]:
    """The residual arrays as stored (base, then each level; after neighbour prediction) of the strands
    of ``cards`` evenly spaced cards (whole cards: neighbour prediction works within them), coded with
    ``plan`` and ``zone``. 64 cards tell the neighbour zone's choice, whose margins are wide, but not
    interpolation widths whose sizes differ by a few per cent: those take 200."""
    ids = np.unique(strand_card)
    picked = ids[np.linspace(0, len(ids) - 1, min(cards, len(ids))).astype(np.int64)]
    pick = np.flatnonzero(np.isin(strand_card, picked))
    base, levels, *_ = encode_uvd(cmap, strand_card[pick], y[pick], scale[pick], plan,
                                  dead_zone=zone.take(pick))
    return with_neighbour_prediction(strand_card[pick], [base] + levels, plan.level_guide)[0]
