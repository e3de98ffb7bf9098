"""Interpolated strands (spec 4.5): strands stored as a blend of two or three others.

Dense hair is mostly made by interpolation: a groom's children are weighted blends of nearby guide
strands (Houdini, XGen, Blender children), and reconstructions are densified the same way. A strand
that such a blend of other strands' decoded points, resampled at even arc length, predicts within the
position tolerance at every point is stored as a *child*: its parents (guides, coded as usual) and
their weights, a few bytes instead of its points (a plain blend, not resampled, where that is
nearer: a groom's children often are). The decoder blends, resamples and carries each
point onto the child's card by the searched Newton steps, so a child has card coordinates like
any other strand. The writer finds the children (:func:`find_children`) and keeps only those whose
decoded points it has checked (:func:`place_children`, on the decoded guides).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import _decoder, _writer
from .geometry import CardMap
from .parallel import map_blocks

WEIGHT_BITS = 10  # weights are integers in units of 2^-WEIGHT_BITS (spec 4.5)
WEIGHT_ONE = 1 << WEIGHT_BITS
CANDIDATES = 24  # a strand's parents are sought among the strands with the nearest roots ...
DESCRIPTOR_POINTS = 10  # ... compared at this many evenly spaced points ...
ROOT_TOLERANCE = 0.01  # ... among pairs and triples whose roots blend to within this x tol of its root
WEIGHT_SLACK = 0.05  # weights may reach this far below 0 and above 1
GOOD_ENOUGH = 0.05  # a search stops at a blend this near (x tol; the weights are fitted again after)
ACCEPT = 0.5  # a strand becomes a child where its blend of the input points lies within this x tol
ROUNDS = 3  # searches at most after the first two (find_children): each among the strands not yet children
NEWTON_STEPS, NEWTON_HALVINGS = 8, 4  # the decoder's searched Newton steps for a child's points


class Children(NamedTuple):
    """Which strands are children, and of which parents (strand indices) with which weights
    (integers summing to WEIGHT_ONE), each blend resampled at even arc length or not."""

    child: np.ndarray  # [S] bool
    parents: np.ndarray  # [S, 3] int64, -1 for guides
    weights: np.ndarray  # [S, 3] int64
    respaced: np.ndarray  # [S] bool


def root_candidates(roots: np.ndarray, k: int) -> np.ndarray:
    """Per strand, the ``k`` other strands with the nearest roots (``[S, k]``, nearest first, -1 where
    fewer), sought in the 27 cells around its own of a grid that holds about ``k`` roots a cell."""
    roots = np.ascontiguousarray(roots, np.float64)
    s = len(roots)
    lo, hi = roots.min(0), roots.max(0)
    extent = np.maximum(hi - lo, 1e-12)
    volume = np.prod(np.sort(extent)[1:]) if s > 1 else 1.0  # roots lie on a surface: its two larger extents
    cell = max(float(np.sqrt(volume * k / max(s, 1))), float(extent.max()) / 1024)
    dims = np.floor(extent / cell).astype(np.int64) + 1
    ijk = np.minimum(np.floor((roots - lo) / cell).astype(np.int64), dims - 1)
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(key, kind="stable")
    keys, starts = np.unique(key[order], return_index=True)
    ends = np.r_[starts[1:], s]
    offsets = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), -1).reshape(-1, 3)
    near = ijk[:, None, :] + offsets[None]  # [S, 27, 3]
    inside = ((near >= 0) & (near < dims)).all(-1)
    near_key = (near[..., 0] * dims[1] + near[..., 1]) * dims[2] + near[..., 2]
    at = np.minimum(np.searchsorted(keys, near_key), len(keys) - 1)
    found = inside & (keys[at] == near_key)
    cell_lo = np.where(found, starts[at], 0).astype(np.int64)
    cell_hi = np.where(found, ends[at], 0).astype(np.int64)
    out = np.empty((s, k), np.int64)
    order = order.astype(np.int64)
    map_blocks(lambda b: _writer.nearest_roots(roots, order, cell_lo[b], cell_hi[b], out[b], b.start), s)
    return out


def fit_weights(targets: np.ndarray, sources: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Least-squares weights ``[n, 3]`` (summing to 1) of the blends of ``sources[parents]`` nearest
    ``targets [n, P, 3]`` (:func:`._writer.fit_blends`)."""
    targets, sources = np.ascontiguousarray(targets, np.float64), np.ascontiguousarray(sources, np.float64)
    parents = np.ascontiguousarray(parents, np.int64)
    out = np.empty((len(targets), 3))
    map_blocks(lambda b: _writer.fit_blends(targets[b], sources, parents[b], out[b]), len(targets))
    return out


def quantize_weights(w: np.ndarray) -> np.ndarray:
    """Weights as integers in units of 1/WEIGHT_ONE summing to WEIGHT_ONE (the first takes the rest)."""
    q = np.rint(w * WEIGHT_ONE).astype(np.int64)
    q[:, 0] = WEIGHT_ONE - q[:, 1] - q[:, 2]
    return q


def blend(guides: np.ndarray, parents: np.ndarray, weights: np.ndarray, respaced: np.ndarray) -> np.ndarray:
    """The children's world points ``[n, P, 3]``: their parents' points ``guides [G, P, 3]`` blended, and
    resampled at even arc length where ``respaced`` (spec 4.5)."""
    guides = np.ascontiguousarray(guides, np.float64)
    parents, weights = np.ascontiguousarray(parents, np.int64), np.ascontiguousarray(weights, np.int64)
    respaced = np.ascontiguousarray(respaced, np.uint8)
    out = np.empty((len(parents),) + guides.shape[1:])
    map_blocks(lambda b: _decoder.blend_strands(guides, parents[b], weights[b], WEIGHT_ONE, respaced[b], out[b]),
               len(parents))
    return out


def _misses(guides: np.ndarray, parents: np.ndarray, weights: np.ndarray, respaced: np.ndarray,
            targets: np.ndarray) -> np.ndarray:
    """Per child, the largest distance between its :func:`blend` and ``targets`` (compiled)."""
    guides, targets = np.ascontiguousarray(guides, np.float64), np.ascontiguousarray(targets, np.float64)
    parents, weights = np.ascontiguousarray(parents, np.int64), np.ascontiguousarray(weights, np.int64)
    respaced, out = np.ascontiguousarray(respaced, np.uint8), np.empty(len(parents))
    map_blocks(lambda b: _writer.blend_misses(guides, parents[b], weights[b], WEIGHT_ONE, respaced[b], targets[b],
                                              out[b]), len(parents))
    return out


def find_children(points: np.ndarray, tol: float) -> Children:
    """The strands of ``points [S, P, 3]`` that a blend of two or three other strands predicts within
    ACCEPT x ``tol``, with their parents and weights, none of them a parent itself: each search finds
    every strand's best blend among its CANDIDATES (:func:`._writer.best_blends`), and strands are
    taken as children best first, their parents then kept as guides."""
    points = np.ascontiguousarray(points, np.float64)
    s, p = points.shape[:2]
    child = np.zeros(s, bool)
    parents = np.full((s, 3), -1, np.int64)
    weights = np.zeros((s, 3), np.int64)
    respaced = np.zeros(s, bool)
    if s < 3 or p < 2:
        return Children(child, parents, weights, respaced)
    roots = np.ascontiguousarray(points[:, 0])
    at = np.linspace(0, p - 1, DESCRIPTOR_POINTS).round().astype(int)
    desc = np.ascontiguousarray(points[:, at].reshape(s, -1))
    along = points[:, np.minimum(at + 1, p - 1)] - points[:, np.maximum(at - 1, 0)]
    tangent = np.ascontiguousarray((along / np.maximum(np.linalg.norm(along, axis=-1, keepdims=True), 1e-300))
                                   .reshape(s, -1))
    cand = root_candidates(roots, CANDIDATES)

    def search(usable: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, ...]:
        """Those of the strands ``rows`` that a blend of ``usable`` strands predicts within ACCEPT x tol:
        the strands, their parents, weights and distances."""
        rows = np.ascontiguousarray(rows, np.int64)
        sub, use = np.ascontiguousarray(cand[rows]), usable.astype(np.uint8)
        f, ww, m = np.full((len(rows), 3), -1, np.int64), np.zeros((len(rows), 3)), np.empty(len(rows))
        map_blocks(lambda b: _writer.best_blends(roots, desc, tangent, rows[b], sub[b], use, ROOT_TOLERANCE * tol,
                                                 WEIGHT_SLACK, GOOD_ENOUGH * tol, f[b], ww[b], m[b]), len(rows))
        ok = np.flatnonzero(m <= tol)
        if len(ok) == 0:
            return ok, np.zeros((0, 3), np.int64), np.zeros((0, 3), np.int64), np.zeros(0, bool), np.zeros(0)
        fit, mode, err = best_weights(points[rows[ok]], points, f[ok], [ww[ok], fit_weights(points[rows[ok]], points,
                                                                                             f[ok])])
        good = err <= ACCEPT * tol
        return rows[ok][good], f[ok][good], fit[good], mode[good], err[good]

    def take(kids, par, fit, mode, err) -> np.ndarray:
        """Make children best first, unless a strand is a parent already or a parent a child; returns
        the strands left out for a parent that is a child."""
        again = np.zeros(s, bool)
        for i in np.argsort(err, kind="stable"):
            t = kids[i]
            if is_parent[t]:
                continue
            if child[par[i]].any():
                again[t] = True
                continue
            child[t], parents[t], weights[t], respaced[t] = True, par[i], fit[i], mode[i]
            is_parent[par[i]] = True
        return again

    # the strands that some blend of others predicts ("alike") become children of strands that none
    # predicts (the likely guides) first; then, best first, of any strands not yet children, their
    # parents staying guides, and a strand whose blend took one that has become a child tries again
    is_parent = np.zeros(s, bool)
    alike = np.zeros(s, bool)
    alike[search(np.ones(s, bool), np.arange(s))[0]] = True
    take(*search(~alike, np.flatnonzero(alike)))
    open_ = alike & ~child & ~is_parent
    for _ in range(ROUNDS):
        open_ = take(*search(~child, np.flatnonzero(open_)))
        if not open_.any():
            break
    return Children(child, parents, weights, respaced)


def best_weights(targets: np.ndarray, sources: np.ndarray, parents: np.ndarray, tries: list[np.ndarray]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of the weights ``tries`` blending ``sources[parents]`` into ``targets [n, P, 3]``, quantized, with
    the blend resampled at even arc length or not, each strand's nearest at its farthest point: the
    weights, whether resampled, and that distance."""
    best = None
    for w in tries:
        q = quantize_weights(w)
        for respaced in (True, False):
            mode = np.full(len(q), respaced)
            err = _misses(sources, parents, q, mode, targets)
            if best is None:
                best = [q, mode, err]
            else:
                better = err < best[2]
                for have, new in zip(best, (q, mode, err), strict=True):
                    have[better] = new[better]
    return best[0], best[1], best[2]


def place_children(cmap: CardMap, step: float, guides: np.ndarray, parents: np.ndarray, weights: np.ndarray,
                   respaced: np.ndarray, card: np.ndarray) -> np.ndarray:
    """The children's card coordinates ``[n, P, 3]`` (float32) on the cards of ``cmap``: blended from
    their parents' world points ``guides`` (:func:`blend`) and carried onto ``card`` by the searched Newton steps,
    each search ending within a hundredth of the point ``step`` (spec 4.5). Raises ValueError
    where float32 cannot hold a coordinate (a corrupt file: the caller says which)."""
    goal = blend(guides, parents, weights, respaced)
    uvd = np.empty(goal.shape, np.float32)
    card = np.ascontiguousarray(card, np.int64)
    per_unit2 = (1.0 / step) * (1.0 / step)  # g_d^2, g_d = 1 / q (spec 4.3)
    bad = sum(map_blocks(lambda b: _decoder.place_points(cmap.frames, cmap.segments, goal[b], card[b], NEWTON_STEPS,
                                                        NEWTON_HALVINGS, per_unit2, uvd[b]), len(goal)))
    if bad:
        raise ValueError(f"{bad} interpolated strand coordinates beyond float32's range")
    return uvd
