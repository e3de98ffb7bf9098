"""Appearance that follows the motion: each Gaussian's view-dependent colour turns with its segment.

A Gaussian's colour is ``c(v) = sum_lm s_lm Y_lm(v)`` over the view direction ``v``. Turned by ``R``
its colour is ``c(R^T v)``, which lies in the same bands: per degree ``l`` the coefficients become
``pinv(A_l) B_l s_l``, with ``A_l`` the band's basis at fixed directions and ``B_l`` the basis at those
directions turned back by ``R`` (exact: the turned colour lies in the band; degree 0 never changes).

A segment's rotation from rest is its card's frame rotation at the nearest spine sample (tangent,
normal, bitangent now against at rest), then the smallest rotation from that-turned rest direction to
the segment's direction now, so a Gaussian follows both the card's twist and its own bend.
"""

from __future__ import annotations

import numpy as np

from ..asset import Cards, HairAsset
from ..gaussians import SH_C1, SH_C2, SH_C3, Gaussians, decode_gaussians, segment_frames
from ..geometry import spine_tangents, strand_points
from .clip import Animation


def _band(dirs: np.ndarray, degree: int) -> np.ndarray:
    """The real SH basis of band ``degree`` (1..3) at unit ``dirs [..., 3]``: ``[..., 2 degree + 1]``, in the
    order and signs of :func:`cghair_format.gaussians.sh_polynomial`."""
    x, y, z = dirs[..., 0], dirs[..., 1], dirs[..., 2]
    if degree == 1:
        return np.stack([-SH_C1 * y, SH_C1 * z, -SH_C1 * x], -1)
    xx, yy, zz = x * x, y * y, z * z
    if degree == 2:
        return np.stack([SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2 * zz - xx - yy), SH_C2[3] * x * z,
                         SH_C2[4] * (xx - yy)], -1)
    return np.stack([SH_C3[0] * y * (3 * xx - yy), SH_C3[1] * x * y * z, SH_C3[2] * y * (4 * zz - xx - yy),
                     SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy), SH_C3[4] * x * (4 * zz - xx - yy),
                     SH_C3[5] * z * (xx - yy), SH_C3[6] * x * (xx - 3 * yy)], -1)


def _probe_directions(degree: int) -> np.ndarray:
    """``4 degree + 2`` fixed directions, twice the band's size, at which its basis has full rank (spread
    at random from a fixed seed: regular spirals of a few points can be singular for a band)."""
    d = np.random.default_rng(degree).normal(size=(4 * degree + 2, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def rotate_sh(sh: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """SH ``[G, (d+1)^2, 3]`` of Gaussians turned by ``rotation [G, 3, 3]`` (or one ``[3, 3]``): the colour
    seen from ``R v`` afterwards is the colour seen from ``v`` before. Float64 in, float64 out."""
    sh = np.asarray(sh, np.float64)
    out = sh.copy()
    degree = int(round(np.sqrt(sh.shape[1]))) - 1
    rotation = np.broadcast_to(np.asarray(rotation, np.float64), (sh.shape[0], 3, 3))
    for band in range(1, degree + 1):
        probes = _probe_directions(band)
        a_inv = np.linalg.pinv(_band(probes, band))
        turned = np.einsum("kj,gji->gki", probes, rotation)  # R^T x_k, as rows: x_k R
        b = _band(turned, band)  # [G, 2l+1, 2l+1]
        lo, hi = band * band, (band + 1) * (band + 1)
        out[:, lo:hi] = np.einsum("jk,gkm,gmc->gjc", a_inv, b, sh[:, lo:hi])
    return out


def spine_frames(cards: Cards) -> np.ndarray:
    """Per spine sample the orthonormal frame ``[t, n, n x t]`` as matrix columns, ``[C, M+1, 3, 3]`` (the
    viewer's GPU decode builds the same frames from the moved cards)."""
    t = spine_tangents(np.asarray(cards.spine, np.float64))
    n = np.asarray(cards.normal, np.float64)
    n = n - t * (n * t).sum(-1, keepdims=True)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)
    return np.stack([t, n, np.cross(n, t)], -1)


def _smallest_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Matrices ``[..., 3, 3]`` of the smallest rotation taking unit ``a`` onto unit ``b`` (identity where
    they are opposite or either is zero)."""
    c = (a * b).sum(-1)[..., None, None]
    k = np.cross(a, b)
    kx = np.zeros(k.shape + (3,))
    kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    kx = kx - np.swapaxes(kx, -1, -2)
    rot = c * np.eye(3) + kx + k[..., :, None] * k[..., None, :] / np.where(c > -1 + 1e-9, 1 + c, 1.0)
    return np.where(c > -1 + 1e-9, rot, np.eye(3))


def segment_samples(asset: HairAsset) -> np.ndarray:
    """The spine sample ``k [S, P-1]`` nearest each segment's middle along its card (whose frame it turns
    with): ``rint(u M)`` of the mean of its end points' ``u``."""
    m = asset.cards.segments
    u = 0.5 * (asset.uvd[:, :-1, 0] + asset.uvd[:, 1:, 0]).astype(np.float64)
    return np.clip(np.rint(u * m), 0, m).astype(np.int64)


def segment_directions(points: np.ndarray) -> np.ndarray:
    """Unit directions ``[S, P-1, 3]`` (float64) of the segments of strands ``points [S, P, 3]`` (zero for a
    segment of zero length)."""
    d = np.diff(np.asarray(points, np.float64), axis=1)
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-30)


def segment_rotations(asset: HairAsset, animation: Animation, frame: int, points: np.ndarray | None = None
                      ) -> np.ndarray:
    """Each segment's rotation from rest to ``frame``, ``[S, P-1, 3, 3]`` (see the module docstring); with
    ``points [S, P, 3]``, onto those strands' segments instead of the driven ones (strands simulated alone,
    say) from the same cards' frames."""
    moved = animation.cards(asset.cards, frame)
    turn = np.einsum("ckij,cklj->ckil", spine_frames(moved), spine_frames(asset.cards))  # F_now F_rest^T
    r_card = turn[asset.strand_card[:, None], segment_samples(asset)]
    rest_points = strand_points(asset.cards, asset.strand_card, asset.uvd)
    rest = np.einsum("spij,spj->spi", r_card, segment_directions(rest_points))
    now = segment_directions(strand_points(moved, asset.strand_card, asset.uvd) if points is None else points)
    return _smallest_rotation(rest, now) @ r_card


def frame_gaussians(asset: HairAsset, animation: Animation, frame: int, turn_sh: bool = True) -> Gaussians:
    """The Gaussians at ``frame``: positions and frames from the moved cards (spec 6.1, 6.2), SH turned
    with each segment (``turn_sh=False``: the rest pose's SH, for comparison)."""
    rest = decode_gaussians(asset)
    points = strand_points(animation.cards(asset.cards, frame), asset.strand_card, asset.uvd)
    means, rotations, scales = segment_frames(points, asset.thickness)
    sh = rest.sh
    if turn_sh:
        padded = segment_rotations(asset, animation, frame).reshape(-1, 3, 3)
        if asset.variable:
            padded = padded[asset.real_segments().ravel()]
        sh = rotate_sh(sh, padded).astype(np.float32)
    if asset.variable:
        real = asset.real_segments().ravel()
        means, rotations, scales = means[real], rotations[real], scales[real]
    return Gaussians(means, rotations, scales, rest.opacities, sh)
