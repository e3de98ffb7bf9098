"""Predictive coding of strand points in card coordinates, guided by world space (spec 4.3).

Card coordinates ``(u, v, delta)`` of a smooth strand are not smooth: the strip is piecewise flat, so
they kink wherever the strand crosses a triangle edge. World positions are smooth. Each refinement
sample is therefore predicted in world space (Lagrange interpolation of the decoded neighbours'
world positions), carried back to card coordinates by Newton steps on the card mapping started from
the card-space interpolation, and only the residual in card coordinates is stored.

Strands of one card run side by side, so their residuals are alike too: with neighbour prediction
(spec 4.3) a strand's residuals are stored as differences from those of the strand next to it on
the card (ordered by root position), level by level and channel by channel where that is smaller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .asset import Cards
from .geometry import CardMap
from .parallel import map_blocks
from .quantize import base_prediction, level_plan

NEWTON_STEPS = 2
MAX_STEP_RATIO = 64.0


@dataclass(frozen=True)
class Prediction:
    """How strand points are predicted (META quant): the base stride, the base samples' predictor
    order (1: the previous base sample, 2: linear extrapolation) and the Newton steps per level."""

    base_stride: int
    base_order: int
    newton_steps: int


def code_base(rec: np.ndarray, base: np.ndarray, order: int, y: np.ndarray | None = None,
              residuals: np.ndarray | None = None) -> np.ndarray:
    """Fill the base samples of ``rec [S, n, 3]``, encoding ``y`` or decoding ``residuals [S, nb, 3]``;
    returns the residuals."""
    out = np.zeros((len(rec), len(base), 3), np.int64) if residuals is None else residuals
    for j, i in enumerate(base):
        pred = base_prediction(rec, base, j, order)
        if residuals is None:
            out[:, j] = np.rint(y[:, i] - pred)
        rec[:, i] = pred + out[:, j]
    return out


def _run(cmap: CardMap, strand_card: np.ndarray, scale: np.ndarray, n: int, plan: Prediction,
         y: np.ndarray | None = None, residuals: tuple[np.ndarray, list[np.ndarray]] | None = None,
         dead_zone: tuple[np.ndarray, float] | None = None):
    """Encode (``y`` given, scaled card coordinates ``[S, n, 3]``) or decode (``residuals`` given).

    ``dead_zone`` (encoding): the input's world points ``[S, n, 3]`` and a distance. A refinement
    sample's residual is left at zero wherever its prediction alone lies within that distance of
    the input point: the error stays bounded, zeros cost the least, and as the decoder predicts
    from what it reconstructs, later samples simply see that reconstruction.

    Returns the reconstruction ``[S, n, 3]`` (scaled units), its world points ``[S, n, 3]`` (when
    decoding, all but the last level's) and the residuals (base ``[S, nb, 3]``, levels ``[S, L, 3]``)."""
    base, levels = level_plan(n, plan.base_stride)
    newton = plan.newton_steps
    s = len(strand_card)
    rec = np.zeros((s, n, 3))
    world = np.zeros((s, n, 3))
    out_base = code_base(rec, base, plan.base_order, y, None if residuals is None else residuals[0])
    world[:, base] = _to_world(cmap, strand_card, rec[:, base], scale)
    out_levels = []
    for li, (idx, nb, wt) in enumerate(levels):
        pred = np.einsum("slkc,lk->slc", rec[:, nb], wt)  # card-space interpolation: the start
        if newton:
            target = np.einsum("slkc,lk->slc", world[:, nb], wt)  # world-space interpolation
            pred = _newton(cmap, strand_card, pred, target, scale, newton)
        if y is not None:
            r = np.rint(y[:, idx] - pred).astype(np.int64)
            if dead_zone is not None:
                miss = _to_world(cmap, strand_card, pred, scale) - dead_zone[0][:, idx]
                r[np.einsum("slc,slc->sl", miss, miss) <= dead_zone[1] ** 2] = 0
        else:
            r = residuals[1][li]
        rec[:, idx] = pred + r
        if y is not None or li < len(levels) - 1:  # the decoder needs no world points after the last level
            world[:, idx] = _to_world(cmap, strand_card, rec[:, idx], scale)
        out_levels.append(r)
    return rec, world, (out_base, out_levels)


def _to_world(cmap: CardMap, strand_card: np.ndarray, scaled: np.ndarray, scale: np.ndarray) -> np.ndarray:
    s, n = scaled.shape[:2]
    uvd = (scaled / scale[:, None, :]).reshape(-1, 3)
    return cmap(np.repeat(strand_card, n), uvd).reshape(s, n, 3)


def _newton(cmap: CardMap, strand_card: np.ndarray, start: np.ndarray, target: np.ndarray, scale: np.ndarray,
            steps: int) -> np.ndarray:
    """``steps`` Newton steps on ``map(c) = target`` from ``start`` (scaled card coordinates)."""
    s, n = start.shape[:2]
    card = np.repeat(strand_card, n)
    sc = np.repeat(scale, n, axis=0)
    c = start.reshape(-1, 3) / sc
    goal = target.reshape(-1, 3)
    for _ in range(steps):
        x, (ju, jv, jd) = cmap(card, c, jacobian=True)
        miss = goal - x
        delta = solve3(ju, jv, jd, miss) * sc
        # keep a step only where it is finite and in proportion to the world-space miss (a step of
        # one unit moves a point by at most one quantization step, so a sane step is not much longer
        # than the miss in steps); near-singular Jacobians give neither
        bound = MAX_STEP_RATIO * np.sqrt(np.einsum("ij,ij->i", miss, miss)) * sc[:, 2] + 1.0
        ok = np.isfinite(delta).all(axis=1) & (np.abs(delta).max(axis=1) <= bound)
        c = c + np.where(ok[:, None], delta, 0.0) / sc
    out = (c * sc).reshape(s, n, 3)
    return np.where(np.isfinite(out), out, start)


def solve3(a: np.ndarray, b: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Solve ``[a b c] x = r`` for many 3x3 systems given by columns ``[N, 3]`` (Cramer's rule);
    a singular system (|det| <= 1e-30) gives x = 0."""
    bc, ca, ab = np.cross(b, c), np.cross(c, a), np.cross(a, b)
    det = np.einsum("ij,ij->i", a, bc)
    ok = np.abs(det) > 1e-30
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    return np.stack([np.einsum("ij,ij->i", r, bc), np.einsum("ij,ij->i", r, ca), np.einsum("ij,ij->i", r, ab)],
                    axis=1) * inv[:, None]


def encode_uvd(cards: Cards, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray, plan: Prediction,
               dead_zone: tuple[np.ndarray, float] | None = None):
    """Residuals (base, levels) of scaled card coordinates ``y [S, P, 3]`` (``uvd * scale``), and the
    world points ``[S, P, 3]`` the decoder will reconstruct. Every reconstructed value is within 0.5
    of ``y``, except refinement samples where ``dead_zone`` (see :func:`_run`) lets a zero residual stand."""
    _, world, (base, levels) = _in_chunks(cards, strand_card, scale, y.shape[1], plan, y=y, dead_zone=dead_zone)
    return base, levels, world


def decode_uvd(cards: Cards, strand_card: np.ndarray, base: np.ndarray, levels: list[np.ndarray], n: int,
               scale: np.ndarray, plan: Prediction) -> np.ndarray:
    """Card coordinates ``[S, n, 3]`` (float64) from the residuals of :func:`encode_uvd`."""
    rec, _, _ = _in_chunks(cards, strand_card, scale, n, plan, residuals=(base, levels))
    return rec / scale[:, None, :]


def _in_chunks(cards: Cards, strand_card: np.ndarray, scale: np.ndarray, n: int, plan: Prediction,
               y: np.ndarray | None = None, residuals=None, dead_zone: tuple[np.ndarray, float] | None = None):
    """:func:`_run` over blocks of strands, which are independent of each other, in parallel."""
    cmap = CardMap(cards)

    def one(b: slice):
        part = None if residuals is None else (residuals[0][b], [r[b] for r in residuals[1]])
        return _run(cmap, strand_card[b], scale[b], n, plan, y=None if y is None else y[b], residuals=part,
                    dead_zone=None if dead_zone is None else (dead_zone[0][b], dead_zone[1]))

    parts = map_blocks(one, len(strand_card))
    rec = np.concatenate([p[0] for p in parts])
    world = np.concatenate([p[1] for p in parts])
    base = np.concatenate([p[2][0] for p in parts])
    levels = [np.concatenate([p[2][1][i] for p in parts]) for i in range(len(parts[0][2][1]))]
    return rec, world, (base, levels)


# --- neighbour prediction across the strands of a card (spec 4.3) ----------------------------------

def neighbour_order(strand_card: np.ndarray, roots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strands ordered by card, then root ``v``, then root ``u``, then index (``roots``: the base
    residuals of sample 0, ``[S, 3]`` integers), and for each position whether it starts its card."""
    order = np.lexsort((roots[:, 0], roots[:, 1], strand_card))
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


def neighbour_decode(d: np.ndarray, order: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Inverse of :func:`neighbour_encode`: a cumulative sum that restarts at each card."""
    total = np.cumsum(d[order], axis=0)
    first = np.flatnonzero(starts)
    before = np.zeros_like(total[first])
    before[1:] = total[first[1:] - 1]
    total -= np.repeat(before, np.diff(np.r_[first, len(order)]), axis=0)
    res = np.empty_like(d)
    res[order] = total
    return res
