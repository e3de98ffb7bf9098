"""Predictive coding of strand points in card coordinates, guided by world space (spec 4.3).

Card coordinates ``(u, v, delta)`` of a smooth strand are not smooth: the strip is piecewise flat, so
they kink wherever the strand crosses a triangle edge. World positions are smooth. Each refinement
sample is therefore predicted in world space (Lagrange interpolation of the decoded neighbours'
world positions), carried back to card coordinates by Newton steps on the card mapping started from
the card-space interpolation, and only the residual in card coordinates is stored, its step on u and
v stretched where the card is locally shorter or narrower than its card-wide scale.

Strands of one card run side by side, so their residuals are alike too: with neighbour prediction
(spec 4.3) a strand's residuals are stored as differences from those of the strand before it on
the card (the writer stores strands card by card, alike strands in turn: :func:`canonical_order`),
array by array and channel by channel where that is smaller.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import _decoder, _writer
from .asset import Cards
from .errors import InvalidContentError
from .geometry import CardMap, card_scales
from .parallel import BLOCK_ROWS, map_threads
from .quantize import base_prediction, level_plan

# At most this many Newton steps per refinement sample; most samples stop after one, within a
# hundredth of a step (spec 4.3). 4 rather than 2: smaller files on wavy hair at no decoding cost, as
# most samples take one step (docs/compression.md, "Newton steps on the card map").
NEWTON_STEPS = 4
# Halving a Newton step that overshoots (the card map is only piecewise smooth: a full step from one
# triangle can land where another bends away): 4 keeps a wavy model's finest samples from residuals of
# thousands of steps; more halvings save little more (docs/compression.md, "Newton steps on the card map").
NEWTON_HALVINGS = 4
# A refinement residual's step on u and v follows the card's local scale, up to this many times the
# card-wide one (spec 4.3): the card-wide scale is the longest rail segment and the widest point, so
# elsewhere a step moves a point less than the tolerance allows. 1.5 makes wavy hair's files smaller and
# leaves flat, even cards as they were; 2 or more leaves a few points beyond the bound, and the writer's
# smaller step then costs more than the stretch saves (docs/compression.md, "Stretched steps").
STRETCH_MAX = 1.5


class DeadZone(NamedTuple):
    """Encoding only (spec 4.3, a writer's MAY): a sample takes a cheaper residual where its
    reconstruction still lies within ``distance`` of the input point (``points [S, n, 3]``, world):
    zero for a refinement sample, and with ``neighbour`` first the residual of its card neighbour
    (the strand coded before it on its card), whose stored difference is then zero. With ``counts``
    (each strand's own point count, spec 3) a placeholder that no kept sample is predicted from takes
    any residual (:func:`free_samples`)."""

    points: np.ndarray
    distance: float
    neighbour: bool = False
    counts: np.ndarray | None = None  # [S] int, or None: every strand keeps all its points

    def take(self, strands: np.ndarray) -> DeadZone:
        """The dead zone of the strands ``strands`` (indices)."""
        return self._replace(points=self.points[strands],
                             counts=None if self.counts is None else self.counts[strands])

    def arrays(self, n: int, plan: Prediction) -> ZoneArrays:
        """The dead zone as :func:`._writer.encode_strands` reads it, for strands of ``n`` points coded
        with ``plan``."""
        free = None if self.counts is None else free_samples(self.counts, n, plan)
        return ZoneArrays(np.ascontiguousarray(self.points, np.float64), float(self.distance), self.neighbour, free)


class ZoneArrays(NamedTuple):
    """A :class:`DeadZone` as the compiled writer reads it: ``points [S, n, 3]`` float64 C-ordered, the
    ``distance`` and ``neighbour``, and ``free [S, n]`` uint8 (:func:`free_samples`; None: every sample
    is kept)."""

    points: np.ndarray
    distance: float
    neighbour: bool
    free: np.ndarray | None


def free_samples(counts: np.ndarray, n: int, plan: Prediction) -> np.ndarray:
    """``[S, n]`` uint8: the samples of strands of ``counts`` points (placeholders after them, spec 3) that
    no sample below a strand's count is predicted from, directly or through others, on ``plan``'s
    coding order: a decoder drops them, so any residual will do. A refinement sample's prediction takes
    its interpolation neighbours (and, ``level_guide``, the most alike strand found on the base samples
    of its base segment and the ones either side); a base sample's the three base samples before it
    (the steps and the most alike strand of ``base_guide`` 2 and 3)."""
    base, levels = level_plan(n, plan.base_stride, plan.level_taps)
    taps = plan.level_taps or (4,) * len(levels)
    out = np.zeros((len(counts), n), np.uint8)
    for count in np.unique(counts):
        needed = np.arange(n) < count
        for (idx, nb, _), t in zip(reversed(levels), reversed(taps), strict=True):  # finest first
            for row in np.flatnonzero(needed[idx]):
                needed[nb[row, :t]] = True  # coarser samples (an unused slot names sample 0, needed anyway)
                if plan.level_guide:
                    k = np.searchsorted(base, idx[row]) - 1
                    needed[base[max(k - 1, 0):k + 3]] = True
        for t in range(len(base) - 1, 0, -1):
            if needed[base[t]]:
                needed[base[max(t - 3, 0):t]] = True
        out[counts == count] = ~needed
    return out


@dataclass(frozen=True)
class Prediction:
    """How strand points are predicted (META quant): the base stride, the base samples' predictor
    order per channel u, v, delta (1: the previous base sample, 2: linear extrapolation), the Newton
    steps per refinement sample, the interpolation neighbours of each level (None: 4 each), how
    many times a Newton step that lands farther from its goal is halved before the search stops, how
    far a residual's step may stretch with the card's local scale (1: not at all), and whether a
    strand's base samples are predicted from its card neighbour's world steps (0: no, 1: yes, 2: scaled
    by how the two strands' previous steps compare, 3: after the first, from the most alike strand
    before it on the card), and whether each base segment's refinement residuals are differences from
    those of the most alike strand before it on the card (``level_guide``)."""

    base_stride: int
    base_order: tuple[int, int, int]
    newton_steps: int
    level_taps: tuple[int, ...] | None = None
    newton_halvings: int = NEWTON_HALVINGS
    stretch_max: float = STRETCH_MAX
    base_guide: int = 0
    level_guide: bool = False


def base_residuals(y: np.ndarray, base: np.ndarray, orders: tuple[int, int, int]) -> np.ndarray:
    """The residuals ``[S, nb, 3]`` of the base samples of ``y [S, n, 3]`` alone (no dead zone): what
    the compiled recurrence stores for them, in numpy, with the predictor ``orders`` of channels u, v,
    delta (the writer's choice)."""
    yt = y.transpose(1, 0, 2)  # sample-major, as base_prediction takes it
    rec = np.zeros(yt.shape)
    out = np.zeros((len(y), len(base), 3), np.int64)
    for ch, order in enumerate(orders):
        for j, i in enumerate(base):
            pred = base_prediction(rec[..., ch], base, j, order)
            out[:, j, ch] = np.rint(yt[i, :, ch] - pred)
            rec[i, :, ch] = pred + out[:, j, ch]
    return out


class Recurrence(NamedTuple):
    """A :class:`Prediction` for strands of ``n`` points as the compiled recurrence reads it
    (:func:`._decoder.decode_strands`, :func:`._writer.encode_strands`): the ``base`` samples and their
    predictor order per channel; levels: ``level_start [L + 1]`` delimits the rows of ``idx [R]`` (the
    samples they predict), ``nb [R, W]`` and ``wt [R, W]`` (interpolation neighbours and weights, the
    first ``level_taps[l]`` columns of level ``l``); with ``level_guide``, ``row_seg [R]``, each row's
    base segment (else None); and the options of the Newton search and of the residuals' steps."""

    base: np.ndarray
    base_order: np.ndarray
    level_start: np.ndarray
    level_taps: np.ndarray
    idx: np.ndarray
    nb: np.ndarray
    wt: np.ndarray
    row_seg: np.ndarray | None
    newton_steps: int
    newton_halvings: int
    stretch_max: float
    base_guide: int


def recurrence(n: int, plan: Prediction) -> Recurrence:
    """``plan``'s :class:`Recurrence` for strands of ``n`` points."""
    base, levels = level_plan(n, plan.base_stride, plan.level_taps)
    width = levels[0][1].shape[1] if levels else 4
    return Recurrence(
        base=base.astype(np.int64), base_order=np.asarray(plan.base_order, np.int64),
        level_start=np.cumsum([0] + [len(idx) for idx, _, _ in levels], dtype=np.int64),
        level_taps=np.asarray(plan.level_taps or (4,) * len(levels), np.int64),
        idx=np.concatenate([np.zeros(0, np.int64)] + [lv[0] for lv in levels]).astype(np.int64),
        nb=np.concatenate([np.zeros((0, width), np.int64)] + [lv[1] for lv in levels]).astype(np.int64),
        wt=np.concatenate([np.zeros((0, width))] + [lv[2] for lv in levels]),
        row_seg=_row_segments(n, plan.base_stride) if plan.level_guide else None,
        newton_steps=plan.newton_steps, newton_halvings=plan.newton_halvings, stretch_max=plan.stretch_max,
        base_guide=plan.base_guide)


class Layout(NamedTuple):
    """Where strands lie, as the compiled recurrence reads it: the cards' triangle ``frames [T, 18]`` and
    ``segments`` (:class:`.geometry.CardMap`), each strand's card ``strand_card [S]`` (int64) and its
    ``scale [S, 3]`` (float64)."""

    frames: np.ndarray
    segments: int
    strand_card: np.ndarray
    scale: np.ndarray


# A block of the compiled recurrence: (plan, layout, strands in coding order, first) -> its result
Block = Callable[[Recurrence, Layout, np.ndarray, int], int]


def _run_strands(cmap: CardMap, strand_card: np.ndarray, scale: np.ndarray, n: int, plan: Prediction, run: Block,
                 after: int = 0) -> int:
    """The compiled recurrence (``run``: :func:`._decoder.decode_strands` or :func:`._writer.encode_strands`
    on the strands it is given) over blocks of whole cards in parallel, card by card, each strand after
    its neighbour (which the base samples' guide reads and the dead zone may copy; a card's triangles
    stay in cache while its strands are coded); the sum of what ``run`` returns. Encoding with
    ``after``, the strands before it are coded already, and each card's others come last on it (``run``
    gets, per card, the position of its first strand to code)."""
    card = np.ascontiguousarray(strand_card, np.int64)
    by_card, starts = neighbour_order(card)
    layout = Layout(cmap.frames, cmap.segments, card, np.ascontiguousarray(scale, np.float64))
    rec = recurrence(n, plan)
    if after == 0:
        return sum(map_threads(lambda b: run(rec, layout, by_card[b], 0), card_blocks(starts)))
    bounds = np.r_[np.flatnonzero(starts), len(card)]
    cards = [(slice(a, b), int(np.count_nonzero(by_card[a:b] < after)))
             for a, b in zip(bounds[:-1], bounds[1:], strict=True) if by_card[b - 1] >= after]
    return sum(map_threads(lambda c: run(rec, layout, by_card[c[0]], c[1]), cards))


def card_blocks(starts: np.ndarray, rows: int = BLOCK_ROWS) -> list[slice]:
    """Slices of about ``rows`` strands of the card-ordered strands (``starts``: where each card's
    begin), each starting where a card does, so no card is split between blocks."""
    first = np.flatnonzero(starts)
    if len(first) == 0:
        return []
    at = np.minimum(np.searchsorted(first, np.arange(0, len(starts), rows)), len(first) - 1)
    bounds = np.r_[np.unique(first[at]), len(starts)]
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


class Coded(NamedTuple):
    """What :func:`encode_uvd` leaves for a later call to go on from: the residuals before the level
    differences, the scaled reconstructions, their world points and the level references, each with
    room for more rows, of which the first ``count`` are coded."""

    residuals: np.ndarray
    rec: np.ndarray
    world: np.ndarray
    level_ref: np.ndarray | None
    count: int


def encode_uvd(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray, plan: Prediction,
               dead_zone: DeadZone | None = None, before: Coded | None = None, room: int = 0):
    """Residuals (base, levels) of scaled card coordinates ``y [S, P, 3]`` (``uvd * scale``) on the cards
    of ``cmap``, the world points ``[S, P, 3]`` the decoder will reconstruct and the :class:`Coded`
    state. Every reconstructed value is within 0.5 of ``y``, except samples where ``dead_zone``
    (:class:`DeadZone`) lets a cheaper
    residual stand: the error stays bounded, the residuals it picks cost the least, and as the decoder
    predicts from what it reconstructs, later samples simply see that reconstruction. With
    ``plan.level_guide`` the levels come as stored: differences from each base segment's reference's.
    With ``room`` rows (more than ``S``) the state can go on: with ``before`` (such a call on the first
    of these strands, with the same cards and plan, and room for all) only the rest are coded, each
    last on its card, and the first strands decode as they did."""
    s, n = y.shape[:2]
    widths = level_widths(n, plan.base_stride)
    if before is not None:
        raw, rec, world, ref, after = before
        if len(rec) < s:
            raise ValueError(f"encode_uvd: the state has room for {len(rec)} strands, not {s}")
    else:
        rows, after = max(s, room), 0
        raw = np.empty((rows, sum(widths), 3), np.int64)
        rec, world = np.empty((rows, n, 3)), np.empty((rows, n, 3))
        ref = np.full((rows, widths[0] - 1), -1, np.int64) if plan.level_guide else None
    zone = None if dead_zone is None else dead_zone.arrays(n, plan)
    state = Coded(raw[:s], rec[:s], world[:s], None if ref is None else ref[:s], s)
    y = np.ascontiguousarray(y, np.float64)
    _run_strands(cmap, strand_card, scale, n, plan,
                 lambda r, layout, strands, first: _writer.encode_strands(r, layout, strands, y, state, zone, first),
                 after)
    # (the levels' differences go to a copy where the raw residuals may be gone on from)
    residuals = raw[:s].copy() if plan.level_guide and (len(raw) > s or before is not None) else raw[:s]
    if plan.level_guide:  # the levels as differences from each base segment's reference's (spec 4.3)
        _writer.level_differences(residuals, ref[:s], _row_segments(n, plan.base_stride), widths[0])
    base, *levels = np.split(residuals, np.cumsum(widths)[:-1], axis=1)
    return base, levels, world[:s], Coded(raw, rec, world, ref, s)


def coded_uvd(coded: Coded, scale: np.ndarray, first: int = 0) -> np.ndarray:
    """The card coordinates (float32) that :func:`decode_uvd` gets for the coded strands from ``first`` on."""
    return (coded.rec[first:coded.count] / scale[first:, None, :]).astype(np.float32)  # as the decoder divides


def _row_segments(n: int, base_stride: int) -> np.ndarray:
    """Per refinement sample (the levels' rows in order), the base segment ``k`` it lies in:
    ``base[k] < i < base[k + 1]`` (spec 4.3, ``level_guide``)."""
    base, levels = level_plan(n, base_stride)
    idx = np.concatenate([np.zeros(0, np.int64)] + [lv[0] for lv in levels])
    return (np.searchsorted(base, idx, side="right") - 1).astype(np.int64)


def level_widths(n: int, base_stride: int) -> list[int]:
    """The widths of the residual arrays of ``n`` points: the base samples, then each level."""
    base, levels = level_plan(n, base_stride)
    return [len(base)] + [len(idx) for idx, _, _ in levels]


def decode_coordinates(cmap: CardMap, strand_card: np.ndarray, residuals: np.ndarray, n: int, scale: np.ndarray,
                       plan: Prediction) -> np.ndarray:
    """Card coordinates ``[S, n, 3]`` in float64 (spec 4.3's ``y / g``, before the rounding to float32)
    from the residuals of :func:`encode_uvd`, side by side in one array ``[S, N, 3]`` (base samples,
    then each level). Raises InvalidContentError where float32 cannot hold them (a corrupt step or
    residuals)."""
    coords = np.empty((len(strand_card), n, 3))
    residuals = np.ascontiguousarray(residuals, np.int64)

    def block(rec: Recurrence, layout: Layout, strands: np.ndarray, _first: int) -> int:
        # each block its own scratch: a strand and those before it that its base samples may follow
        scratch = [np.empty((_decoder.SCRATCH_STRANDS, n, 3)) for _ in range(2)]
        return _decoder.decode_strands(rec, layout, strands, residuals, coords, *scratch)

    bad = _run_strands(cmap, strand_card, scale, n, plan, block)
    if bad:
        raise InvalidContentError(f"{bad} strand point coordinates decode beyond float32's range (a corrupt "
                                  f"step, scale or residuals)", chunk="STRD")
    return coords


def decode_uvd(cmap: CardMap, strand_card: np.ndarray, residuals: np.ndarray, n: int, scale: np.ndarray,
               plan: Prediction) -> np.ndarray:
    """:func:`decode_coordinates` rounded to float32: the decoded strands' ``uvd``."""
    return decode_coordinates(cmap, strand_card, residuals, n, scale, plan).astype(np.float32)


# --- neighbour prediction across the strands of a card (spec 4.3) ----------------------------------

CHAIN_SAMPLES = 8  # the strand features the writer's order compares: every this many points ...
CHAIN_WINDOW = 256  # ... among this many candidates at most


def canonical_order(cards: Cards, strand_card: np.ndarray, uvd: np.ndarray) -> np.ndarray:
    """The order the writer stores strands in (spec 4.3): card by card; on each card a greedy chain
    that starts at the strand with the smallest root ``v`` and goes on to the most alike strand not yet
    taken: its root and its steps between every CHAIN_SAMPLES-th point, in card coordinates times
    world units. Each strand's neighbour, the one before it, is then as alike as the writer could make
    it (in shape more than in place, as neighbour prediction wants), and ``strand_card`` runs in blocks."""
    su, sv = card_scales(cards, 0.0)
    card = strand_card.astype(np.int64)
    world = np.stack([su, sv, np.ones_like(su)], axis=-1)[card][:, None, :]
    samples = uvd[:, ::CHAIN_SAMPLES].astype(np.float64) * world
    features = np.ascontiguousarray(np.concatenate([samples[:, :1], np.diff(samples, axis=1)], axis=1)
                                    .reshape(len(card), -1))
    by_card = np.lexsort((np.arange(len(card)), uvd[:, 0, 1], card))
    group_start = np.searchsorted(card[by_card], np.arange(cards.count + 1)).astype(np.int64)
    out = np.empty(len(card), np.int64)
    _writer.chain_order(features, by_card.astype(np.int64), group_start, CHAIN_WINDOW, out)
    return out


def neighbour_order(strand_card: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strands ordered by card, then by index (a stable sort), and for each position whether it starts
    its card: a strand's neighbour is the one before it in this order, on the same card."""
    order = np.argsort(strand_card, kind="stable")
    cards = strand_card[order]
    starts = np.r_[True, cards[1:] != cards[:-1]]
    return order, starts


def neighbour_encode(r: np.ndarray, order: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Residuals ``[S, ...]`` minus those of the previous strand of the same card in ``order``."""
    rs = r[order]
    out = rs.copy()
    out[1:] -= rs[:-1]
    out[starts] = rs[starts]
    res = np.empty_like(r)
    res[order] = out
    return res


def neighbour_decode(values: np.ndarray, order: np.ndarray, starts: np.ndarray, mask: np.ndarray) -> None:
    """Inverse of :func:`neighbour_encode` on residuals ``[S, N, 3]`` (int64, C order), in place, for the
    columns and channels where ``mask [N, 3]`` is set: a sum that restarts at each card (compiled)."""
    _decoder.undo_neighbour(values, np.ascontiguousarray(order, np.int64), starts.astype(np.uint8),
                           np.ascontiguousarray(mask, np.uint8))
