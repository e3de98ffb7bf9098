"""Cards fitted to animated strands: motion from DCC tools (USD or Alembic strand caches).

A strand point is stored as ``(u, v, delta)`` on its card (spec 6.1): ``x = A + f Ef + e Ev + delta nh``,
that is ``x = sum_j beta_j V_j + delta nh`` over the point's triangle, with ``nh`` the normalized
``(1 - f) n_k + f n_(k+1)``. Holding each point's ``l = |(1 - f) n_k + f n_(k+1)|`` at the last estimate,
``x`` is linear in the card's rail points ``L_k, R_k`` and normals ``n_k``: with a card's unknowns ordered
``L_k, R_k, n_k`` by ``k``, each point touches 5 unknowns at most 5 apart, so the least squares of the
whole groom is one symmetric banded system (6 diagonals; the three coordinates share the matrix),
solved by banded Cholesky. Per frame :func:`fit_frames`

1. carries each card's rest strip by the best rigid fit (Kabsch) of its strands' rest points to their
   points in the frame (a card with fewer than 3 points, or points on a line, takes the whole groom's):
   the prior a Tikhonov term draws the solution to, so that what a card's strands do not determine of
   its strip (a card of one strand turning about it, the tip past its strands' ends) moves rigidly;
2. measures, with a free fit (the prior all but off), how far each card's strands are from moving as
   one strip (:func:`_inconsistency`); where they stray, rails that few points pin keep the rigid
   strip's shape (:func:`_add_shape`), so strands pulling apart at a sparse tip do not stretch it; and
   carries a card's tail (the spine points past the last whose rails the data hold) with the free
   fit's last held points instead of the whole card (:func:`_tail_prior`): a bent card's tip follows
   the part next to it, and a tail far off no longer folds the tip back and flips its normal;
3. solves :data:`ROUNDS` times, each with ``l`` from the last normals and the last solution as the prior
   (iterated Tikhonov: the pull toward the prior of an unknown the data determine with weight ``s``
   shrinks by ``lambda / (lambda + s)`` a round, an undetermined one stays at the prior), projecting each
   onto the card model (:func:`_project`): the spine is the rails' midpoint, the normal perpendicular to
   its tangent; half-widths stay the rest pose's, as :class:`~.clip.Animation` requires;
4. optionally (``refine``) takes Gauss-Newton steps on the exact card model (:func:`_refine`), which
   does what the linear rounds cannot: they leave the spine past a card's last points to the prior,
   while the tangent at those points depends on it.

The previous frame's normals start the next. On the small asset of the tests, lambda 1e-3 and 5 rounds
recover bent cards to 1e-10 of the bbox diagonal (1e-6 in one round leaves a bias of 2e-6; weaker priors
let cards of 1-2 strands follow noise further); cut strands are followed to 6e-2 of it by the linear
rounds and to 2e-3 after the two Gauss-Newton steps.

The residual of a frame is the distance from each of the file's points to the point the fitted cards
decode, as a fraction of the rest groom's bounding-box diagonal."""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..asset import Cards, HairAsset
from ..errors import CghError, require
from ..geometry import bounding_diagonal, card_rails, cross, lengths, spine_tangents, triangle_and_barycentrics
from .clip import Animation

TIKHONOV = 1e-3  # weight of the prior, relative to a card's mean data weight per unknown
ROUNDS = 5  # solves per frame: each takes l from the last normals and the last solution as its prior
MAX_REFINE = 16  # Gauss-Newton steps a fit may ask for (each keeps a card only where it comes closer)
GN_TIKHONOV = 1e-6  # weight of the pull toward the linear solution in those steps, relative as TIKHONOV
LEVENBERG = 1e-9  # damping of a Gauss-Newton step (a normal's length and tangent part are free), relative
FREE = 1e-9  # the Tikhonov weight of the probe fit that measures how far strands stray from one strip
EXACT = 0.1  # strands that stray less than this share of a card's half-width from one strip move as one;
INCONSISTENT = 0.2  # from EXACT to EXACT + this, the rest shape's weight grows from 0 to full...
SUPPORT = 0.25  # ...on the rails the data weigh less than this share of the card's mean
PAIRS = np.triu_indices(5)  # the 15 pairs (i <= j) of a point's 5 unknowns
FLAT = 1e-6  # a card's strands whose rest spread has a second axis under this share of the first are on a line
HELD = 0.05  # a spine point is held by the data where each rail weighs this share of the card's mean rail
ANCHOR = 3  # held spine points (both rails each) before a card's tail that carry its rest tail (_tail_prior)


class FitError(CghError, ValueError):
    """Animated strands that cannot drive the asset (counts, order, non-finite points)."""


@dataclass
class Residuals:
    """Per frame, the point error of the fitted cards against the given strands, as a fraction of the rest
    groom's bounding-box diagonal (``diagonal`` scene units), and the seconds the fit took."""

    mean: np.ndarray  # [F]
    max: np.ndarray  # [F]
    seconds: np.ndarray  # [F]
    diagonal: float

    def summary(self) -> str:
        """One line: the frames, the mean and worst of the per-frame errors and the fit time."""
        return (f"fitted {len(self.mean)} frames: point error mean {self.mean.mean():.2e} (worst frame "
                f"{self.mean.max():.2e}), max {self.max.max():.2e} of the bbox diagonal "
                f"({self.diagonal:.4g} units); {1e3 * self.seconds.mean():.0f} ms a frame")


@dataclass
class _Layout:
    """Where each real strand point sits on its card: what stays fixed from frame to frame."""

    pick: tuple[np.ndarray, np.ndarray]  # (strand, point) indices of the real points, [N] each
    card: np.ndarray  # [N] int64
    cols: np.ndarray  # [N, 5] the point's unknowns in the banded system: 3 rail points, then n_k, n_(k+1)
    bary: np.ndarray  # [N, 3] weights of the 3 rail points
    g: np.ndarray  # [N, 2] weights (1 - f, f) of n_k, n_(k+1)
    delta: np.ndarray  # [N] scaled by the card's normal scale
    scale: np.ndarray  # [C] the unknown for n_k is scale * n_k, so its weights are as large as the rails'
    unknowns: int  # 3 (M + 1) per card
    uvd: np.ndarray  # [N, 3] float64, the points' stored card coordinates
    order: np.ndarray  # [N, 5] the order of each point's unknowns that sorts them (``sorted`` below)
    sorted: np.ndarray  # [N, 5] each point's unknowns, ascending
    band: np.ndarray  # [N, 15] where each pair of them (i <= j) adds to the upper band [6, n], flat
    anchor: np.ndarray  # [C] the last spine point whose two rails the data hold (:data:`HELD`), -1: none


def _layout(asset: HairAsset) -> _Layout:
    cards = asset.cards
    m, c_count = cards.segments, cards.count
    s_idx, p_idx = np.nonzero(asset.real_points())
    uvd = asset.uvd[s_idx, p_idx].astype(np.float64)
    card = asset.strand_card[s_idx].astype(np.int64)
    tri, bary = triangle_and_barycentrics(uvd[:, :2], m)
    k, upper = tri // 2, (tri % 2).astype(bool)
    f = uvd[:, 0] * m - k
    # unknowns of card c: 3k + (0: L_k, 1: R_k, 2: n_k); lower triangle (L_k, R_k, L_k+1), upper (R_k, R_k+1, L_k+1)
    rails = np.where(upper[:, None], np.stack([3 * k + 1, 3 * k + 4, 3 * k + 3], 1),
                     np.stack([3 * k, 3 * k + 1, 3 * k + 3], 1))
    unknowns = 3 * (m + 1)
    cols = np.concatenate([rails, 3 * k[:, None] + np.array([2, 5])], 1) + card[:, None] * unknowns
    # the normal's unknown is scaled by the card's RMS |delta|, so its weights are of order 1 like the rails'
    sq = np.bincount(card, uvd[:, 2] ** 2, c_count) / np.maximum(np.bincount(card, minlength=c_count), 1)
    scale = np.maximum(np.sqrt(sq), 1e-9 * bounding_diagonal(cards.spine))
    order = np.argsort(cols, axis=1)  # ascending, so that each pair (i <= j) is in the upper band
    ordered = np.take_along_axis(cols, order, 1)
    size = c_count * unknowns
    band = (5 - (ordered[:, PAIRS[1]] - ordered[:, PAIRS[0]])) * size + ordered[:, PAIRS[1]]
    rail = np.bincount(cols[:, :3].ravel(), (bary * bary).ravel(), size).reshape(c_count, m + 1, 3)[..., :2]
    held = (rail >= HELD * rail.mean(axis=(1, 2))[:, None, None]).all(-1)  # [C, M+1]
    anchor = np.where(held.any(1), m - np.argmax(held[:, ::-1], axis=1), -1)
    return _Layout((s_idx, p_idx), card, cols, bary, np.stack([1 - f, f], 1), uvd[:, 2] / scale[card], scale,
                   unknowns, uvd, order, ordered, band, anchor)


def _normal_lengths(lay: _Layout, normal: np.ndarray) -> np.ndarray:
    """Each point's ``l = |(1 - f) n_k + f n_(k+1)|`` for card normals ``[C, M+1, 3]``."""
    flat = normal.reshape(-1, 3)
    n = lay.g[:, :1] * flat[lay.cols[:, 3] // 3] + lay.g[:, 1:] * flat[lay.cols[:, 4] // 3]
    return np.maximum(lengths(n), 1e-30)


def _kabsch(rest: np.ndarray, now: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation ``[3, 3]`` and translation ``[3]`` taking points ``rest [N, 3]`` closest to ``now``."""
    cr, cn = rest.mean(0), now.mean(0)
    u, _, vt = np.linalg.svd((rest - cr).T @ (now - cn))
    rot = (u @ np.diag([1, 1, np.sign(np.linalg.det(u @ vt))]) @ vt).T
    return rot, cn - rot @ cr


def _card_kabsch(lay: _Layout, rest: np.ndarray, now: np.ndarray, c_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per card, the rigid transform ``[C, 3, 3], [C, 3]`` of its strands' points from ``rest [N, 3]`` to
    ``now [N, 3]``; the whole groom's where a card's points do not fix a rotation."""
    count = np.bincount(lay.card, minlength=c_count).astype(np.float64)
    den = np.maximum(count, 1)[:, None]
    cr = np.stack([np.bincount(lay.card, rest[:, i], c_count) for i in range(3)], 1) / den
    cn = np.stack([np.bincount(lay.card, now[:, i], c_count) for i in range(3)], 1) / den
    a, b = rest - cr[lay.card], now - cn[lay.card]
    h = np.stack([np.bincount(lay.card, a[:, i] * b[:, j], c_count) for i in range(3) for j in range(3)],
                 1).reshape(-1, 3, 3)
    u, s, vt = np.linalg.svd(h)
    sign = np.sign(np.linalg.det(u @ vt))
    d = np.ones((c_count, 3))
    d[:, 2] = np.where(sign == 0, 1, sign)
    rot = np.swapaxes((u * d[:, None, :]) @ vt, 1, 2)
    spread = np.bincount(lay.card, (a * a).sum(1), c_count)
    weak = (count < 3) | (s[:, 1] <= FLAT * np.maximum(s[:, 0], 1e-300)) | (spread <= 0)
    g_rot, g_shift = _kabsch(rest, now)
    rot[weak] = g_rot
    shift = cn - np.einsum("cij,cj->ci", rot, cr)
    shift[weak & (count == 0)] = g_shift
    return rot, shift


def _unknowns(lay: _Layout, cards: Cards) -> np.ndarray:
    """The banded system's unknowns ``[C * 3(M+1), 3]`` of ``cards``: ``L_k, R_k, scale * n_k`` per ``k``."""
    rails = card_rails(cards)  # [C, M+1, 2, 3]
    n = cards.normal.astype(np.float64) * lay.scale[:, None, None]
    return np.concatenate([rails, n[:, :, None]], 2).reshape(-1, 3)


def _coefficients(lay: _Layout, l_point: np.ndarray) -> np.ndarray:
    """Each point's weights ``[N, 5]`` of its unknowns ``lay.cols``: 3 rail points, then 2 scaled normals."""
    return np.concatenate([lay.bary, lay.g * (lay.delta / l_point)[:, None]], 1)


def _system(lay: _Layout, now: np.ndarray, l_point: np.ndarray, prior: np.ndarray, rigid: np.ndarray,
            shape: np.ndarray, weight: float = TIKHONOV) -> tuple[np.ndarray, np.ndarray]:
    """The normal equations of the least squares for points ``now [N, 3]``, drawn to ``prior`` (Tikhonov,
    ``weight``) and, where the data are thin, to the shape of ``rigid`` (:func:`_add_shape`, ``shape [C]``
    a card): the upper band ``[6, n]`` of their symmetric matrix (solveh_banded's layout) and the
    right-hand sides ``[n, 3]``."""
    size = len(prior)
    coef = np.take_along_axis(_coefficients(lay, l_point), lay.order, 1)
    pairs = coef[:, PAIRS[0]] * coef[:, PAIRS[1]]
    band = np.bincount(lay.band.ravel(), pairs.ravel(), 6 * size).reshape(6, size)
    rhs = np.stack([np.bincount(lay.sorted.ravel(), (coef * now[:, x, None]).ravel(), size) for x in range(3)], 1)
    mean = np.repeat(np.maximum(band[5].reshape(-1, lay.unknowns).mean(1), 1.0), lay.unknowns)
    _add_shape(band, rhs, mean, np.repeat(shape, lay.unknowns), rigid, lay.unknowns)
    band[5] += weight * mean
    return band, rhs + (weight * mean)[:, None] * prior


def _add_shape(band: np.ndarray, rhs: np.ndarray, mean: np.ndarray, shape: np.ndarray, rigid: np.ndarray,
               unknowns: int) -> None:
    """Add, where the data weigh an unknown less than :data:`SUPPORT` of its card's mean, terms that keep
    the rigidly carried rest strip's shape: each rail's step to the next spine point and each rail-to-rail
    gap, weighted by the card's mean weight, ``shape`` and how thin the data are there."""
    thin = np.clip(1 - band[5] / (SUPPORT * mean), 0, 1)
    index = np.arange(len(mean))
    slot, k = index % unknowns % 3, index % unknowns // 3
    last = unknowns // 3 - 1
    for offset, first in ((3, (k < last) & (slot < 2)), (1, slot == 0)):  # rails along the card; L_k to R_k
        i = index[first]
        j = i + offset
        kappa = shape[i] * mean[i] * np.maximum(thin[i], thin[j])
        step = rigid[i] - rigid[j]
        band[5, i] += kappa
        band[5, j] += kappa
        band[5 - offset, j] -= kappa
        rhs[i] += kappa[:, None] * step
        rhs[j] -= kappa[:, None] * step


def _solve(lay: _Layout, now: np.ndarray, l_point: np.ndarray, prior: np.ndarray, rigid: np.ndarray,
           shape: np.ndarray, weight: float = TIKHONOV) -> np.ndarray:
    """The least-squares unknowns ``[C * 3(M+1), 3]`` of points ``now [N, 3]`` (:func:`_system`)."""
    from scipy.linalg import solveh_banded

    band, rhs = _system(lay, now, l_point, prior, rigid, shape, weight)
    return solveh_banded(band, rhs, check_finite=False)


def _project(lay: _Layout, solution: np.ndarray, rest: Cards, prior_normal: np.ndarray) -> tuple[np.ndarray,
                                                                                                  np.ndarray]:
    """The card model nearest the fitted rails and normals: spines and unit normals ``[C, M+1, 3]``.

    The spine is the rails' midpoint. The normal is an angle about the tangent that both the rails
    (``t x (R - L)``, the normal their direction implies) and the fitted normal suggest; turning it by a
    small angle moves a rail point by ``w`` times it and a point off the card by ``delta`` times it,
    so the two are averaged with weights ``w^2`` and the card's mean ``delta^2`` (the rigid prior's
    normal where both vanish)."""
    y = solution.reshape(rest.count, -1, 3, 3)  # [C, M+1, (L, R, scale * n), 3]
    spine = (y[:, :, 0] + y[:, :, 1]) / 2
    t = spine_tangents(spine)
    w = rest.half_width.astype(np.float64)[..., None]
    n = w * cross(t, y[:, :, 1] - y[:, :, 0]) / 2 + lay.scale[:, None, None] * y[:, :, 2]  # length^2 each
    n -= (n * t).sum(-1, keepdims=True) * t
    scale = np.maximum(w[..., 0], lay.scale[:, None]) ** 2
    n = np.where((lengths(n) > 1e-6 * scale)[..., None], n, prior_normal)
    return spine, _perpendicular_normals(spine, n)


def _perpendicular_normals(spine: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """Unit normals ``[C, M+1, 3]``: ``raw`` made perpendicular to the spines' tangents."""
    t = spine_tangents(spine)
    n = raw - (raw * t).sum(-1, keepdims=True) * t
    return n / np.maximum(lengths(n), 1e-30)[..., None]


def _model_unknowns(lay: _Layout, rest: Cards, spine: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """The banded system's unknowns of cards of spines ``spine`` and normals ``raw`` (made perpendicular
    to the spine, unit) at the rest pose's half-widths."""
    return _unknowns(lay, Cards(spine, _perpendicular_normals(spine, raw), rest.half_width, rest.group))


def _owners(m1: int, color: int | None) -> np.ndarray:
    """For each spine point ``k'``, the point ``k`` that moves it when every ``k`` of ``k mod 3 == color``
    moves (a spine point moves its neighbours' tangents, so those 3 apart move disjoint sets); ``-1``
    where none does. ``color`` None: normals, each moving only its own point."""
    k = np.arange(m1)
    if color is None:
        return k
    owner = np.full(m1, -1)
    for offset in (-1, 0, 1):
        near = k + offset
        hit = (near >= 0) & (near < m1) & (near % 3 == color)
        owner[hit] = near[hit]
    return owner


def _jacobian(lay: _Layout, rest: Cards, spine: np.ndarray, raw: np.ndarray, step: float):
    """The sparse Jacobian ``[3 n, 6 C (M+1)]`` of the unknowns (each coordinate a row) with respect to
    the spine points and raw normals (6 a spine point): central differences, 12 pairs of evaluations
    in all, each moving every card and every third spine point at once."""
    from scipy.sparse import csr_matrix

    c_count, m1 = spine.shape[:2]
    rows, cols, vals = [], [], []
    row = np.arange(c_count * m1 * 9).reshape(c_count, m1, 9)  # unknown (c, k, slot) coordinate x: row
    for which, colors in ((0, (0, 1, 2)), (3, (None,))):
        for color in colors:
            owner = _owners(m1, color)
            moved = np.flatnonzero(owner == np.arange(m1)) if color is not None else np.arange(m1)
            for d in range(3):
                diff = []
                for sign in (1, -1):
                    q = [spine.copy(), raw.copy()]
                    q[which // 3][:, moved, d] += sign * step
                    diff.append(_model_unknowns(lay, rest, *q).reshape(c_count, m1, 9))
                value = (diff[0] - diff[1]) / (2 * step)
                k_has = np.flatnonzero(owner >= 0)
                param = (np.arange(c_count)[:, None] * m1 + owner[k_has][None, :]) * 6 + which + d  # [C, k]
                rows.append(row[:, k_has].ravel())
                cols.append(np.repeat(param.ravel(), 9))
                vals.append(value[:, k_has].ravel())
    size = c_count * m1
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(size * 9, size * 6))


def _banded_matrix(band: np.ndarray):
    """The sparse symmetric matrix of an upper band ``[6, n]`` (solveh_banded's layout)."""
    from scipy.sparse import diags

    n = band.shape[1]
    upper = [band[5 - d, d:] for d in range(1, 6)]
    return diags([band[5], *upper, *upper], [0, *range(1, 6), *range(-1, -6, -1)], shape=(n, n), format="csr")


def _refine(lay: _Layout, rest: Cards, now: np.ndarray, spine: np.ndarray, normal: np.ndarray,
            rigid: np.ndarray, shape: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """``steps`` Gauss-Newton steps on the card model itself (spine points and normals, the rest
    half-widths), each damped toward where it starts by the Tikhonov term; a card takes a step only where
    it brings its points (decoded exactly, spec 6.1) closer to the frame's."""
    from scipy.sparse import eye, kron
    from scipy.sparse.linalg import spsolve

    step = 1e-7 * bounding_diagonal(spine)
    start = _model_unknowns(lay, rest, spine, normal)
    error = _card_errors(lay, rest, spine, normal, now)
    for _ in range(steps):
        y0 = _model_unknowns(lay, rest, spine, normal)
        band, rhs = _system(lay, now, _normal_lengths(lay, normal), start, rigid, shape, GN_TIKHONOV)
        h = _banded_matrix(band)
        grad = (rhs - h @ y0).ravel()
        jac = _jacobian(lay, rest, spine, normal, step)
        normal_eq = (jac.T @ kron(h, eye(3), format="csr") @ jac).tocsc()
        normal_eq += LEVENBERG * normal_eq.diagonal().mean() * eye(normal_eq.shape[0], format="csc")
        dq = spsolve(normal_eq, jac.T @ grad).reshape(spine.shape[0], -1, 6)
        new_spine = spine + dq[..., :3]
        new_normal = _perpendicular_normals(new_spine, normal + dq[..., 3:])
        new_error = _card_errors(lay, rest, new_spine, new_normal, now)
        better = new_error < error
        spine = np.where(better[:, None, None], new_spine, spine)
        normal = np.where(better[:, None, None], new_normal, normal)
        error = np.where(better, new_error, error)
    return spine, normal


def _card_errors(lay: _Layout, rest: Cards, spine: np.ndarray, normal: np.ndarray, now: np.ndarray
                 ) -> np.ndarray:
    """Per card, the summed squared distance ``[C]`` of its strands' decoded points from ``now``."""
    from ..geometry import CardMap

    decoded = CardMap(Cards(spine, normal, rest.half_width, rest.group))(lay.card, lay.uvd)
    return np.bincount(lay.card, ((decoded - now) ** 2).sum(1), rest.count)


def _check_frame(asset: HairAsset, f: int, frame: np.ndarray) -> np.ndarray:
    """The frame's points in the asset's strand order, ``[S, P, 3]`` float64, or a one-line FitError."""
    frame = np.asarray(frame)
    s, p = asset.n_strands, asset.points_per_strand
    if frame.ndim != 3 or frame.shape[2] != 3:
        raise FitError(f"frame {f}: strand points must be [strands, points, 3], got shape {frame.shape}")
    ids = asset.strand_ids
    if ids is None and frame.shape[0] != s:
        raise FitError(f"frame {f} has {frame.shape[0]} strands, the asset {s} (and no strand ids to match them"
                       "): export the cache from the groom the .cgh was built from")
    if ids is not None and frame.shape[0] <= int(ids.max()):
        raise FitError(f"frame {f} has {frame.shape[0]} strands, but the asset's strand ids reach "
                       f"{int(ids.max())}: export the cache from the groom the .cgh was built from")
    if frame.shape[1] != p:
        raise FitError(f"frame {f} has {frame.shape[1]} points a strand, the asset {p}: export the cache "
                       "with the point counts of the groom the .cgh was built from")
    if ids is not None:
        frame = frame[ids.astype(np.int64)]
    if not np.isfinite(frame).all():
        raise FitError(f"frame {f} holds NaN or infinite points")
    return frame.astype(np.float64)


def fit_frames(asset: HairAsset, frames: Iterable[np.ndarray], fps: float = 30.0, start: float = 0.0,
               source: str = "", refine: int = 0) -> tuple[Animation, Residuals]:
    """Fit the asset's cards to animated strands: ``frames`` yields each frame's points ``[S, P, 3]`` of the
    source's strands (mapped by the asset's ``strand_ids`` where it has them, else in the asset's order;
    placeholder points after a shorter strand's own are ignored). ``refine`` Gauss-Newton steps on the exact
    card model follow the linear fit (2 bring points on cards their strands do not reach the end of 30
    times closer; on strands that stray from one strip they gain 3-4% for 1.5-2.4 times the time: see
    docs/animation.md). Returns the animation and the residuals."""
    if not (isinstance(refine, (int, np.integer)) and 0 <= refine <= MAX_REFINE):
        raise FitError(f"refine must be a whole number of Gauss-Newton steps in 0..{MAX_REFINE}, got {refine!r}")
    if not (np.isfinite(fps) and 0 < fps <= 1000 and np.isfinite(start)):  # what Animation.validate asks
        raise FitError(f"the frame rate must lie in (0, 1000] and the start be finite, got {fps} and {start}")
    for module in ("scipy.linalg", "scipy.sparse.linalg"):  # imported here, not in the first frame's time
        require(module, "cards", "fitting cards to animated strands", package="scipy")
    rest = asset.cards
    lay = _layout(asset)
    rest_points = _decoded(asset, rest)[lay.pick]
    diagonal = bounding_diagonal(rest_points)
    spines, normals, mean, worst, seconds = [], [], [], [], []
    normal = rest.normal.astype(np.float64)
    for f, frame in enumerate(frames):
        now = _check_frame(asset, f, frame)[lay.pick]
        t0 = time.perf_counter()
        spine, normal = _fit_frame(lay, rest, rest_points, now, normal, refine)
        seconds.append(time.perf_counter() - t0)
        cards = Cards(spine.astype(np.float32), normal.astype(np.float32), rest.half_width, rest.group)
        err = lengths(_decoded(asset, cards)[lay.pick] - now) / diagonal
        spines.append(cards.spine)
        normals.append(cards.normal)
        mean.append(float(err.mean()))
        worst.append(float(err.max()))
    if not spines:
        raise FitError("the animated strands hold no frames")
    animation = Animation(np.stack(spines), np.stack(normals), float(fps), float(start), source)
    animation.validate(rest)
    return animation, Residuals(np.array(mean), np.array(worst), np.array(seconds), diagonal)


def _decoded(asset: HairAsset, cards: Cards) -> np.ndarray:
    from ..geometry import CardMap

    return CardMap(cards).strands(asset.strand_card, asset.uvd)


def _fit_frame(lay: _Layout, rest: Cards, rest_points: np.ndarray, now: np.ndarray, normal: np.ndarray,
               refine: int) -> tuple[np.ndarray, np.ndarray]:
    """One frame's spines and normals ``[C, M+1, 3]`` (float64), from the previous frame's ``normal``."""
    rot, shift = _card_kabsch(lay, rest_points, now, rest.count)
    prior_spine = np.einsum("cij,ckj->cki", rot, rest.spine.astype(np.float64)) + shift[:, None]
    prior_normal = np.einsum("cij,ckj->cki", rot, rest.normal.astype(np.float64))
    rigid = _unknowns(lay, Cards(prior_spine, prior_normal, rest.half_width, rest.group))
    for _ in range(2):  # the free probe, the second time with l from its own normals
        l_point = _normal_lengths(lay, normal)
        free = _solve(lay, now, l_point, rigid, rigid, np.zeros(rest.count), FREE)
        normal = _project(lay, free, rest, prior_normal)[1]
    shape = _inconsistency(lay, rest, free, l_point, now)
    rigid, prior_normal = _tail_prior(lay, rest, free, rigid, prior_normal)
    prior = rigid
    for _ in range(ROUNDS):
        prior = _solve(lay, now, _normal_lengths(lay, normal), prior, rigid, shape)
        spine, normal = _project(lay, prior, rest, prior_normal)
    return _refine(lay, rest, now, spine, normal, rigid, shape, refine) if refine else (spine, normal)


def _tail_prior(lay: _Layout, rest: Cards, free: np.ndarray, rigid: np.ndarray, prior_normal: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The rigid prior (unknowns ``[C * 3(M+1), 3]`` and normals ``[C, M+1, 3]``) with each card's tail, the
    spine points past ``lay.anchor``, carried instead by the rigid motion that takes the rest rails of the
    :data:`ANCHOR` points up to the anchor onto the free fit's there. The data do not fix a tail (a tip
    past its strands' ends, or one rail of it): it follows the part of the card next to it, which the data
    hold, not the whole card, whose motion differs from a bent or whipping tip's by as much as the tip's
    length; a tail far off pulls the tangent and normal of the last points the strands do reach."""
    c_count, m1 = rest.spine.shape[:2]
    tail = np.flatnonzero((lay.anchor >= ANCHOR - 1) & (lay.anchor < m1 - 1))
    if not len(tail):
        return rigid, prior_normal
    window = lay.anchor[tail, None] + np.arange(1 - ANCHOR, 1)  # [T, ANCHOR]
    rest_rails = card_rails(rest)[tail]  # [T, M+1, 2, 3]
    src = np.take_along_axis(rest_rails, window[..., None, None], 1).reshape(len(tail), -1, 3)
    fitted = free.reshape(c_count, m1, 3, 3)[tail]
    dst = np.take_along_axis(fitted[:, :, :2], window[..., None, None], 1).reshape(len(tail), -1, 3)
    cs, cd = src.mean(1, keepdims=True), dst.mean(1, keepdims=True)
    u, _, vt = np.linalg.svd(np.swapaxes(src - cs, 1, 2) @ (dst - cd))
    d = np.ones((len(tail), 3))
    d[:, 2] = np.where(np.linalg.det(u @ vt) < 0, -1.0, 1.0)
    rot = np.swapaxes((u * d[:, None, :]) @ vt, 1, 2)  # [T, 3, 3]
    shift = cd[:, 0] - np.einsum("tij,tj->ti", rot, cs[:, 0])
    after = np.arange(m1)[None, :] > lay.anchor[tail, None]  # [T, M+1]
    rails = np.einsum("tij,tkrj->tkri", rot, rest_rails) + shift[:, None, None]
    normal = np.einsum("tij,tkj->tki", rot, rest.normal[tail].astype(np.float64))
    carried = np.concatenate([rails, (normal * lay.scale[tail, None, None])[:, :, None]], 2)
    out, prior_normal = rigid.reshape(c_count, m1, 3, 3).copy(), prior_normal.copy()
    out[tail] = np.where(after[..., None, None], carried, out[tail])
    prior_normal[tail] = np.where(after[..., None], normal, prior_normal[tail])
    return out.reshape(-1, 3), prior_normal


def _inconsistency(lay: _Layout, rest: Cards, solution: np.ndarray, l_point: np.ndarray, now: np.ndarray
                   ) -> np.ndarray:
    """Per card, how far its strands are from moving as one strip, 0 to 1: the RMS distance of its points
    from the free fit (rails and normals unconstrained, the prior all but off) as a share of its mean
    half-width, less :data:`EXACT`, over :data:`INCONSISTENT`. It weighs the rest shape where the data are
    thin: a strip its strands determine exactly keeps their shape, one they pull apart keeps its own where
    they are few."""
    fitted = (_coefficients(lay, l_point)[:, :, None] * solution[lay.cols]).sum(1)
    sq = np.bincount(lay.card, ((fitted - now) ** 2).sum(1), rest.count)
    rms = np.sqrt(sq / np.maximum(np.bincount(lay.card, minlength=rest.count), 1))
    width = np.maximum(rest.half_width.astype(np.float64).mean(1), 1e-30)
    return np.clip((rms / width - EXACT) / INCONSISTENT, 0.0, 1.0)


def animation_from_file(asset: HairAsset, path: str | Path, refine: int = 0) -> tuple[Animation, Residuals]:
    """The asset's cards fitted to the animated strands of a USD (time-sampled BasisCurves) or Alembic
    file, at the file's frame rate and start time, in the asset's units where the file states its own;
    the residuals say how closely they follow."""
    from ..exchange.strand_cache import load_cache

    cache = load_cache(path)
    ids = np.arange(asset.n_strands) if asset.strand_ids is None else asset.strand_ids.astype(np.int64)
    if asset.strand_ids is None and len(cache.counts) != asset.n_strands:
        raise FitError(f"{path} has {len(cache.counts)} curves, the asset {asset.n_strands} strands (and no strand "
                       "ids to match them): export the cache from the groom the .cgh was built from")
    if len(ids) and int(ids.max()) >= len(cache.counts):
        raise FitError(f"{path} has {len(cache.counts)} curves, but the asset's strand ids reach {int(ids.max())}"
                       ": export the cache from the groom the .cgh was built from")
    wrong = np.flatnonzero(cache.counts[ids] != asset.counts)
    if len(wrong):
        s = int(wrong[0])
        raise FitError(f"{path}: {len(wrong)} strands have other point counts than the asset's (strand {s}: "
                       f"{int(cache.counts[ids[s]])} points in the file, {int(asset.counts[s])} in the asset)"
                       ": export the cache with the point counts of the groom the .cgh was built from")
    # a cache that states its units is brought to the asset's (Blender writes metres, Houdini often cm)
    scale = 1.0 if cache.meters_per_unit is None else cache.meters_per_unit / asset.meters_per_unit
    frames = (f * scale for f in cache.padded(asset.points_per_strand))
    return fit_frames(asset, frames, cache.fps, cache.start, f"fit {Path(path).name}", refine)


def residual_lines(residuals: Residuals, fps: float, start: float = 0.0) -> list[str]:
    """Per frame, its time and the fitted cards' mean and max point error (a fraction of the bbox
    diagonal), then :meth:`Residuals.summary`: what ``cgh animate --from`` prints."""
    lines = [f"{'frame':>6} {'time s':>8} {'mean':>9} {'max':>9} {'ms':>6}"]
    for f, (mean, worst, sec) in enumerate(zip(residuals.mean, residuals.max, residuals.seconds, strict=True)):
        lines.append(f"{f:6d} {start + f / fps:8.3f} {mean:9.2e} {worst:9.2e} {1e3 * sec:6.0f}")
    return [*lines, residuals.summary()]
