"""Stage 4: inverse UV mapping. Each strand point as ``(u, v, delta)`` on its card.

The decode (:func:`cghair_format.geometry.strand_points`) maps ``(u, v, delta)`` to
``pos(f, v) + delta * normalize(n(f))`` where, on segment ``k`` with ``f = uM - k``, ``pos`` is
linear in ``(f, v)`` on each of the segment's two triangles and the interpolated normal
``n(f) = (1 - f) n_k + f n_k+1`` depends on ``f`` only (both rails share the node's normal).
So on one triangle, ``x - pos(f, v)`` must be parallel to the plane spanned by the triangle's
``v`` edge ``e`` and ``n(f)``: ``(x - O - f a) . (e x n(f)) = 0``, a quadratic in ``f``. Its roots
give ``v`` and ``delta`` in closed form. Every point is solved exactly (to float64 rounding) on the
segments around its nearest spine point, both triangles, both roots; the valid solution nearest to
the card (smallest ``|delta|``, inside the strip) wins. This is the L2 optimum of the mapping error
(zero), reached without iterations, against exactly the decode's mesh.

Strands that leave their card's strip are handled by widening the card at the nodes they cross
and extending its end nodes along the spine, then solving again (a few rounds). Inside the strip
the mapping is continuous; outside it the extrapolated half-planes change direction at segment
ends and can leave gaps, so points without a solution near the strip widen their card too. A point
that still has none takes the best exact solution up to 64 strip widths off the strip (never observed
on the real models at the default settings; counted in ``CardBuild.outside_strip``), or else keeps its
nearest-spine coordinates (``CardBuild.unsolved_points``).
"""

from __future__ import annotations

import numpy as np

from ..asset import Cards
from ..geometry import CardMap, card_mesh
from ..parallel import map_blocks
from ._util import chunks, progress
from .normals import consistent_signs, orthonormalize

NEIGHBOURS = 1  # segments tried on each side of the nearest one (then all, for the few unsolved)
EPS_F = 1e-9  # tolerance on the segment coordinate and the triangle test
OUTSIDE_PENALTY = 4.0  # cost of leaving the strip, per unit of strip width, vs |delta|
PLAUSIBLE_OUTSIDE = 1.0  # near the start guess, accept only solutions at most a strip width off the strip
RETRY_OUTSIDE = 4.0  # on the other segments, at most 4 strip widths (or end segments) off it: farther
# solutions are exact in float but wild (huge delta), and quantize badly; such points widen the card
STRIP_TOLERANCE = 1e-3  # v in [-tol, 1 + tol] counts as inside the strip
WIDEN_MARGIN = 1.02
UNSOLVED_WIDEN = 1.5  # an unsolved point widens its card at least this much
MAX_WIDEN = 4.0  # per round: a card widens at most 4x ...
MAX_EXTEND = 1.0  # ... and each end segment grows by at most its own length ...
MAX_END_SEGMENT = 3.0  # ... up to this many times the card's mean segment length
ROUNDS = 6
LAST_RESORT_OUTSIDE = 64.0  # strip widths (or end segments) off the strip: beyond, an "exact" solution is a
# near-degenerate root (u, v, delta of 1e7 and more, past what the format holds: asset.MAX_CARD_COORDINATE)
# and the point keeps its nearest-spine coordinates, counted as unsolved


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...c,...c->...", a, b)


def _solve_triangle(x, origin, a, e, n0, dn, upper: bool, k, m, outside_limit: float):
    """Candidate ``(f, v, delta, cost)`` ``[n, J, 2]`` for one triangle type on segments ``k [n, J]``."""
    q = x - origin
    c0 = _cross(e, n0)
    c1 = _cross(e, dn)
    qa, qb, qc = -_dot(a, c1), _dot(q, c1) - _dot(a, c0), _dot(q, c0)
    scale = np.maximum(np.abs(qa) + np.abs(qb) + np.abs(qc), 1e-300)
    linear = np.abs(qa) < 1e-12 * scale
    disc = qb * qb - 4 * qa * qc
    real = disc >= 0
    sq = np.sqrt(np.maximum(disc, 0.0))
    half = -0.5 * (qb + np.where(qb >= 0, sq, -sq))
    with np.errstate(divide="ignore", invalid="ignore"):
        f1 = np.where(linear, -qc / qb, half / qa)
        f2 = np.where(linear, np.nan, qc / half)
    f = np.stack([f1, f2], axis=-1)  # [n, J, 2]
    ok = np.isfinite(f) & (real | linear)[..., None]
    f = np.where(ok, f, 0.0)
    r = q[..., None, :] - f[..., None] * a[..., None, :]
    nf = n0[..., None, :] + f[..., None] * dn[..., None, :]
    en = _cross(np.broadcast_to(e[..., None, :], nf.shape), nf)
    den = _dot(en, en)
    ok &= den > 1e-300
    den = np.maximum(den, 1e-300)
    v = _dot(_cross(r, nf), en) / den
    delta = _dot(_cross(np.broadcast_to(e[..., None, :], r.shape), r), en) / den * np.linalg.norm(nf, axis=-1)
    if upper:
        v = v + 1.0
        ok &= f + v >= 1 - EPS_F
    else:
        ok &= f + v <= 1 + EPS_F
    kk = k[..., None]
    ok &= (f >= -EPS_F) | (kk == 0)
    ok &= (f <= 1 + EPS_F) | (kk == m - 1)
    width = np.linalg.norm(e, axis=-1)[..., None]
    length = np.linalg.norm(a, axis=-1)[..., None]
    out_v = np.maximum(np.maximum(-v, v - 1), 0.0)
    out_f = np.maximum(np.maximum(-f, f - 1), 0.0)
    cost = np.abs(delta) + OUTSIDE_PENALTY * (out_v * width + out_f * length)
    ok &= (out_v <= outside_limit) & (out_f <= outside_limit)
    cost = np.where(ok & np.isfinite(cost), cost, np.inf)
    return f, v, delta, cost


def solve_uvd(cards: Cards, points: np.ndarray, card: np.ndarray, s: np.ndarray,
              neighbours: int = NEIGHBOURS, show_progress: bool = False,
              retry_outside: float = RETRY_OUTSIDE) -> tuple[np.ndarray, np.ndarray]:
    """Card coordinates ``[N, 3]`` (float64) of ``points [N, 3]`` on cards ``card [N]``, and a mask
    ``[N]`` of the points solved exactly. ``s [N]`` is each point's spine parameter (start guess).

    Points with no plausible exact solution near ``s`` (none, or only ones more than a strip width
    off the strip) are retried on every segment of their card, where the best solution at most
    ``RETRY_OUTSIDE`` off the strip wins; a point still unsolved keeps its nearest-spine
    coordinates (an error the caller reports, and :func:`fit_strip` widens the card for).
    """
    m = cards.segments
    mesh = card_mesh(cards)
    rails = mesh.vertices.astype(np.float64).reshape(cards.count, m + 1, 2, 3)
    left, right = rails[:, :, 0], rails[:, :, 1]
    nrm = cards.normal.astype(np.float64)
    uvd = np.zeros((len(points), 3))
    solved = np.zeros(len(points), bool)
    offsets = np.arange(-neighbours, neighbours + 1)
    for a0, b0 in progress(chunks(len(points)), "uv mapping", show_progress):
        c = card[a0:b0].astype(np.int64)[:, None]
        k0 = np.clip(np.floor(s[a0:b0]), 0, m - 1).astype(np.int64)
        k = np.clip(k0[:, None] + offsets[None, :], 0, m - 1)  # [n, J]
        uvd[a0:b0], solved[a0:b0] = _solve_on(points[a0:b0], c, k, left, right, nrm, m, PLAUSIBLE_OUTSIDE)
    retry = np.flatnonzero(~solved)
    if len(retry):
        k_all = np.broadcast_to(np.arange(m)[None, :], (len(retry), m))
        for a0, b0 in chunks(len(retry), max(1, 65536 // m)):
            idx = retry[a0:b0]
            res, ok = _solve_on(points[idx], card[idx].astype(np.int64)[:, None], k_all[a0:b0],
                                left, right, nrm, m, retry_outside)
            uvd[idx[ok]] = res[ok]
            solved[idx[ok]] = True
    lost = np.flatnonzero(~solved)
    if len(lost):  # fall back to the nearest spine point, across and along the normal
        uvd[lost] = _nearest_guess(cards, points[lost], card[lost], s[lost])
    return uvd, solved


def _solve_on(x, c, k, left, right, nrm, m, outside_limit: float):
    x = x.astype(np.float64)[:, None, :]
    best = []
    for upper in (False, True):
        if upper:
            origin, a, e = right[c, k], right[c, k + 1] - right[c, k], right[c, k + 1] - left[c, k + 1]
        else:
            origin, a, e = left[c, k], left[c, k + 1] - left[c, k], right[c, k] - left[c, k]
        n0, dn = nrm[c, k], nrm[c, k + 1] - nrm[c, k]
        f, v, delta, cost = _solve_triangle(x, origin, a, e, n0, dn, upper, k, m, outside_limit)
        u = (k[..., None] + f) / m
        best.append((np.stack([u, v, delta], -1).reshape(len(x), -1, 3), cost.reshape(len(x), -1)))
    cand = np.concatenate([b[0] for b in best], axis=1)
    cost = np.concatenate([b[1] for b in best], axis=1)
    pick = np.argmin(cost, axis=1)
    rows = np.arange(len(x))
    return cand[rows, pick], np.isfinite(cost[rows, pick])


def _nearest_guess(cards: Cards, points, card, s):
    from ..geometry import card_bitangents

    m = cards.segments
    sc = np.clip(s, 0, m)
    k = np.clip(np.floor(sc), 0, m - 1).astype(np.int64)
    f = (sc - k)[:, None]
    sp = cards.spine.astype(np.float64)
    centre = (1 - f) * sp[card, k] + f * sp[card, k + 1]
    b = card_bitangents(cards).astype(np.float64)[card, k]
    w = cards.half_width.astype(np.float64)[card, k]
    d = points - centre
    v = 0.5 + _dot(d, b) / np.maximum(2 * w, 1e-30)
    return np.stack([sc / m, v, _dot(d, cards.normal.astype(np.float64)[card, k])], -1)


def fit_strip(cards: Cards, points: np.ndarray, card: np.ndarray, s: np.ndarray,
              show_progress: bool = False) -> tuple[Cards, np.ndarray, np.ndarray, int]:
    """Solve every point's ``(u, v, delta)``, widening and extending cards that strands leave.

    Returns the (possibly widened) float32 cards, ``uvd [N, 3]`` float64, the solved mask and the
    number of adjustment rounds used.
    """
    m = cards.segments
    spine = cards.spine.astype(np.float64)
    half = cards.half_width.astype(np.float64)
    normal = cards.normal.astype(np.float64)
    current = cards
    uvd, solved = solve_uvd(current, points, card, s, show_progress=show_progress)
    rounds = 0
    for rounds in range(1, ROUNDS + 1):  # noqa: B007 - the count is returned
        v, u = uvd[:, 1], uvd[:, 0]
        # unsolved points are widened for too: outside the strip the mapping jumps at segment ends
        # (its extrapolated half-planes change direction there) and can leave gaps; inside it cannot
        out_v = (v < -STRIP_TOLERANCE) | (v > 1 + STRIP_TOLERANCE) | ~solved
        out_u = (u < -STRIP_TOLERANCE / m) | (u > 1 + STRIP_TOLERANCE / m)
        if not (out_v.any() or out_u.any()):
            rounds -= 1
            break
        changed = np.zeros(current.count, bool)
        if out_v.any():
            idx = np.flatnonzero(out_v)
            kk = np.clip(np.floor(u[idx] * m), 0, m - 1).astype(np.int64)
            need = np.minimum(np.abs(2 * v[idx] - 1) * WIDEN_MARGIN, MAX_WIDEN)
            need = np.where(solved[idx], need, np.clip(need, UNSOLVED_WIDEN, MAX_WIDEN))
            flat = card[idx].astype(np.int64) * (m + 1)
            factor = np.ones(current.count * (m + 1))
            np.maximum.at(factor, flat + kk, need)
            np.maximum.at(factor, flat + kk + 1, need)
            half *= factor.reshape(current.count, m + 1)
            changed[card[idx]] = True
        if out_u.any():
            for end, sel in ((0, u < -STRIP_TOLERANCE / m), (m, u > 1 + STRIP_TOLERANCE / m)):
                if not sel.any():
                    continue
                beyond = np.zeros(current.count)
                fu = u[sel] * m if end == 0 else u[sel] * m - m  # segments beyond the end (signed)
                (np.minimum if end == 0 else np.maximum).at(beyond, card[sel], fu)
                inner = 1 if end == 0 else m - 1
                seg = spine[:, end] - spine[:, inner]
                seg_len = np.linalg.norm(seg, axis=-1)
                mean_len = np.linalg.norm(np.diff(spine, axis=1), axis=-1).mean(1)
                room = np.maximum(MAX_END_SEGMENT * mean_len / np.maximum(seg_len, 1e-30) - 1, 0.0)
                spine[:, end] += np.minimum(np.abs(beyond) * WIDEN_MARGIN, np.minimum(MAX_EXTEND, room))[:, None] * seg
                changed[card[sel]] = True
            normal = consistent_signs(orthonormalize(normal, spine))
        current = Cards(spine.astype(np.float32), normal.astype(np.float32), half.astype(np.float32),
                        cards.group)
        redo = np.flatnonzero(changed[card])
        s_redo = s[redo]
        res, ok = solve_uvd(current, points[redo], card[redo], s_redo, show_progress=show_progress)
        uvd[redo], solved[redo] = res, ok
    lost = np.flatnonzero(~solved)
    if len(lost):  # last resort: an exact solution far off the strip beats an approximation, within reason
        res, ok = solve_uvd(current, points[lost], card[lost], s[lost], retry_outside=LAST_RESORT_OUTSIDE)
        uvd[lost[ok]], solved[lost[ok]] = res[ok], True
    return current, uvd, solved, rounds


def points_on_cards(cards: Cards, cmap: CardMap, strand_card: np.ndarray, uvd: np.ndarray, points: np.ndarray,
                    atol: float) -> tuple[np.ndarray, float]:
    """The card coordinates ``[S, P, 3]`` of world ``points [S, P, 3]`` on ``cards`` (``cmap`` their
    map), strand ``s`` on card ``strand_card[s]``, from nearby coordinates ``uvd`` (on slightly other
    cards, such as the input's before quantization, or before the points moved), and the largest
    distance left between a point and its coordinates' image. Newton steps (compiled) solve nearly
    every point; the few they leave farther than ``atol`` off (off the strip, where the mapping folds)
    are solved exactly (:func:`solve_uvd`) where that is nearer."""
    s, p = uvd.shape[:2]
    card = np.repeat(strand_card.astype(np.int64), p)
    flat_uvd, flat_points = uvd.reshape(-1, 3), points.reshape(-1, 3)
    out, miss = np.empty((s * p, 3)), np.empty(s * p)

    def block(b: slice) -> None:
        out[b], miss[b] = cmap.invert(card[b], flat_uvd[b], flat_points[b])

    map_blocks(block, s * p, 1 << 16)
    off = np.flatnonzero(miss > atol)
    if len(off):
        exact, _ = solve_uvd(cards, flat_points[off], card[off], out[off, 0] * cards.segments)
        exact_miss = np.linalg.norm(cmap(card[off], exact) - flat_points[off], axis=-1)
        nearer = exact_miss < miss[off]
        out[off[nearer]], miss[off[nearer]] = exact[nearer], exact_miss[nearer]
    return out.reshape(s, p, 3), float(miss.max(initial=0.0))
