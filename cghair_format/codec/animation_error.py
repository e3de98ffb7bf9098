"""The writer's measure of an animation (spec 4.6): the largest distance of a strand point on the decoded
frames from the same point on the input frames, found exactly without mapping every point of every frame.

A strand point is affine in its card triangle's corners plus its depth along the blended normal (spec 6.1:
``x = A + f Ef + g Ev + delta * normalize(Na + f Nef)``; the normal blends along the quad only). So on
two versions of a frame the distance of a point is at most the largest, over the corners of the box that
the triangle's points span in ``(f, g)``, of the rails' part, plus the largest ``|delta|`` times how far
the blended normal can turn (``|a - b| / sqrt(|a| |b|)`` bounds the distance of ``a/|a|`` from ``b/|b|``),
plus a margin for the float32 rounding of the mapped points. These bounds cost a few operations a
triangle; the points are then mapped as the decoder maps them (:class:`..geometry.CardMap`) on those
cards of those frames alone whose bound exceeds the largest distance found so far, worst bound first.
The result is the number that mapping every point gives (:func:`reference_point_error`, which the tests
hold it to), at a small share of the cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..animation.clip import Animation
from ..asset import Cards
from ..geometry import CardMap, card_rails, dot, lengths, strand_points

ROUNDING_MARGIN = 2.0**-20  # of a point's magnitude: covers float32 rounding of both points (2 x sqrt(3) x 2^-24)
FIRST_BATCH, MAX_BATCH = 64, 1024  # (frame, card) pairs mapped at once: the worst bounds, then more as needed


@dataclass(frozen=True)
class PointBoxes:
    """Where the strands' points lie on each card triangle, ``[C, M, 2]`` (quad ``k``, lower/upper), and
    what that fixes of the bounds: how far their barycentrics reach (the largest ``sum |beta_j|``, 1 inside
    the triangle, more where a point extrapolates), how far their normal blend's weights reach, the range
    of ``f`` on each quad, their largest ``|delta|``, whether any lies there; with the strands of each card,
    to map a card's points alone."""

    corners: np.ndarray  # [4, C, M, 2, 2] the corners (f, g) of the box of the points' (f, g)
    spread: np.ndarray  # [C, M, 2] the largest sum |beta_j| over that box
    blend: np.ndarray  # [C, M] the largest |1 - f| + |f| over the quad's points
    f: np.ndarray  # [C, M, 2] the least and greatest f on the quad
    depth: np.ndarray  # [C, M, 2] the largest |delta|
    occupied: np.ndarray  # [C, M, 2] bool
    strands: np.ndarray  # [S] strand indices by card
    starts: np.ndarray  # [C + 1] card c's strands are strands[starts[c]:starts[c + 1]]

    @classmethod
    def of(cls, uvd: np.ndarray, strand_card: np.ndarray, cards: int, segments: int) -> PointBoxes:
        """The boxes of the points ``uvd [S, P, 3]`` on cards ``strand_card [S]`` of ``segments`` segments,
        each point on the triangle card_map (``_arithmetic.pxi``) puts it on, in the same float64 steps:
        ``f`` its fraction of the quad, ``g = v - upper``."""
        m = segments
        u, v, d = (uvd[..., i].astype(np.float64).ravel() for i in range(3))
        s = u * m
        k = np.floor(s)
        k = np.where(k >= 0, k, 0.0)
        k = np.minimum(k, m - 1)
        f = s - k
        upper = f + v > 1
        g = v - upper
        card = np.repeat(np.asarray(strand_card, np.int64), uvd.shape[1])
        key = (card * m + k.astype(np.int64)) * 2 + upper
        n = cards * m * 2
        box = [np.full(n, np.inf), np.full(n, -np.inf), np.full(n, np.inf), np.full(n, -np.inf), np.zeros(n)]
        for into, ufunc, values in zip(box, (np.minimum, np.maximum) * 2 + (np.maximum,), (f, f, g, g, np.abs(d)),
                                       strict=True):
            ufunc.at(into, key, values)
        occupied = np.isfinite(box[0])
        if not (np.isfinite(f).all() and np.isfinite(g).all() and np.isfinite(d).all()):
            occupied[:], box[4][:] = True, np.inf  # a point NaN or infinite: no bound, every card is mapped
        lo_f, hi_f, lo_g, hi_g, depth = (np.where(occupied, a, 0.0).reshape(cards, m, 2) for a in box)
        lower = np.arange(2) == 0
        corners = [(a, b) for a in (lo_f, hi_f) for b in (lo_g, hi_g)]
        # barycentrics of (L_k, R_k, L_k+1) on the lower triangle: (1 - f - g, g, f); of (R_k, R_k+1, L_k+1)
        # on the upper: (1 - f, f + g, -g); their sum of magnitudes is convex, greatest at a corner
        spread = np.max([np.where(lower, np.abs(1 - a - b) + np.abs(b) + np.abs(a),
                                  np.abs(1 - a) + np.abs(a + b) + np.abs(b)) for a, b in corners], axis=0)
        quad_f = np.stack([np.where(occupied.reshape(cards, m, 2), lo_f, np.inf).min(-1),
                           np.where(occupied.reshape(cards, m, 2), hi_f, -np.inf).max(-1)], -1)
        quad_f[~np.isfinite(quad_f)] = 0.0
        blend = np.maximum(np.abs(1 - quad_f[..., 0]) + np.abs(quad_f[..., 0]),
                           np.abs(1 - quad_f[..., 1]) + np.abs(quad_f[..., 1]))
        order = np.argsort(strand_card, kind="stable")
        starts = np.searchsorted(np.asarray(strand_card)[order], np.arange(cards + 1))
        return cls(np.array([np.stack([a, b], -1) for a, b in corners]), spread, blend, quad_f, depth,
                   occupied.reshape(cards, m, 2), order, starts)


def _affine(rails: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each triangle's ``A, Ef, Ev`` ``[C, M, 2, 3]`` from rails ``[C, M+1, 2, 3]`` (CardMap's frame:
    lower ``(L_k, R_k, L_k+1)``, upper ``(R_k, R_k+1, L_k+1)``); linear in the rails."""
    left, right = rails[:, :, 0], rails[:, :, 1]
    a = np.stack([left[:, :-1], right[:, :-1]], axis=2)
    ef = np.stack([left[:, 1:] - left[:, :-1], right[:, 1:] - right[:, :-1]], axis=2)
    ev = np.stack([right[:, :-1] - left[:, :-1], right[:, 1:] - left[:, 1:]], axis=2)
    return a, ef, ev


def _corner_max(x: np.ndarray) -> np.ndarray:
    """The largest of ``x [C, M+1, 2]`` (a value per rail point) over each triangle's corners ``[C, M, 2]``:
    lower ``(L_k, R_k, L_k+1)``, upper ``(R_k, R_k+1, L_k+1)``."""
    left, right = x[:, :, 0], x[:, :, 1]
    shared = np.maximum(right[:, :-1], left[:, 1:])
    return np.stack([np.maximum(shared, left[:, :-1]), np.maximum(shared, right[:, 1:])], axis=2)


def _least_length(base: np.ndarray, slope: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The least ``|base + t slope|`` over ``t`` in ``[f[..., 0], f[..., 1]]``, vectors ``[..., 3]``."""
    ss = dot(slope, slope)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(ss > 0, -dot(base, slope) / ss, f[..., 0])
    t = np.clip(t, f[..., 0], f[..., 1])
    return lengths(base + t[..., None] * slope)


def card_bounds(source: Cards, decoded: Cards, boxes: PointBoxes) -> np.ndarray:
    """Per card ``[C]``, a bound on the distance of any of its strand points on ``decoded`` from the same
    point on ``source`` (float32 points as :func:`..geometry.strand_points` gives them): the rails' part at
    the corners of the points' box, the normal's the largest ``|delta|`` times the turn of the blended
    normal, and a margin for the rounding of both points to float32."""
    rails = card_rails(source)
    da, df, dg = _affine(card_rails(decoded) - rails)
    rails_moved = np.max([lengths(da + c[..., :1] * df + c[..., 1:] * dg) for c in boxes.corners], axis=0)
    ns, nd = source.normal.astype(np.float64), decoded.normal.astype(np.float64)
    moved = lengths(nd - ns)
    apart = boxes.blend * np.maximum(moved[:, :-1], moved[:, 1:])  # the blends' distance, [C, M]
    least = _least_length(ns[:, :-1], ns[:, 1:] - ns[:, :-1], boxes.f)  # the source blend's least length
    with np.errstate(divide="ignore", invalid="ignore"):  # |a/|a| - b/|b|| <= |a - b| / sqrt(|a| |b|)
        turn = np.where(least - apart > 1e-6, np.minimum(apart / np.sqrt(least * (least - apart)), 2.0), 2.0)
    bound = rails_moved + boxes.depth * turn[..., None]
    size = boxes.spread * _corner_max(lengths(rails)) + boxes.depth  # how large the points' coordinates are
    bound = bound + ROUNDING_MARGIN * (2 * size + bound)
    bound = np.where(np.isnan(bound), np.inf, bound)  # (no bound: the card is mapped)
    same = ((source.spine == decoded.spine).all(axis=(1, 2)) & (source.normal == decoded.normal).all(axis=(1, 2)))
    return np.where(same, 0.0, np.where(boxes.occupied, bound, 0.0).max(axis=(1, 2)))  # (same cards: same points)


def _mapped_error(pairs: np.ndarray, boxes: PointBoxes, source: Animation, decoded: Animation, rest: Cards,
                  uvd: np.ndarray) -> float:
    """The largest distance of a strand point on the cards of ``pairs`` (``[n, 2]`` frame, card), each
    point mapped as :func:`..geometry.strand_points` maps it."""
    fr, cd = pairs[:, 0], pairs[:, 1]
    counts = boxes.starts[cd + 1] - boxes.starts[cd]
    strands = np.concatenate([boxes.strands[boxes.starts[c]:boxes.starts[c + 1]] for c in cd])
    card = np.repeat(np.arange(len(pairs), dtype=np.int64), counts)
    points = uvd[strands]

    def mapped(clip: Animation) -> np.ndarray:
        cards = Cards(clip.spine[fr, cd], clip.normal[fr, cd], rest.half_width[cd], rest.group[cd])
        return CardMap(cards).strand_points(card, points)

    return float(lengths(mapped(source).astype(np.float64) - mapped(decoded)).max(initial=0.0))


def animation_point_error(boxes: PointBoxes, source: Animation, decoded: Animation, rest: Cards,
                          uvd: np.ndarray) -> float:
    """The largest distance, over every frame, of a strand point on the decoded frame from the same point
    (its ``uvd``) on the input frame; ``boxes`` (:meth:`PointBoxes.of`) are the points' places."""
    bounds = np.stack([card_bounds(source.cards(rest, t), decoded.cards(rest, t), boxes)
                       for t in range(source.frames)])
    order = np.argsort(-bounds, axis=None, kind="stable")
    worst, done, batch = 0.0, 0, FIRST_BATCH
    while done < len(order) and bounds.flat[order[done]] > worst:
        take = order[done:done + batch]
        take = take[bounds.flat[take] > worst]
        pairs = np.stack(np.unravel_index(take, bounds.shape), axis=1)
        worst = max(worst, _mapped_error(pairs, boxes, source, decoded, rest, uvd))
        done, batch = done + batch, min(2 * batch, MAX_BATCH)
    return worst


def reference_point_error(uvd: np.ndarray, strand_card: np.ndarray, source: Animation, decoded: Animation,
                          rest: Cards) -> float:
    """:func:`animation_point_error` the plain way, every point of every frame mapped (the reference)."""
    worst = 0.0
    for t in range(source.frames):
        a = strand_points(source.cards(rest, t), strand_card, uvd)
        b = strand_points(decoded.cards(rest, t), strand_card, uvd)
        worst = max(worst, float(lengths(a.astype(np.float64) - b).max(initial=0.0)))
    return worst
