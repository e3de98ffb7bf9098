"""Card strips and the card-to-world mapping of strand points (spec: "Card strips", "Strand points").

A card of ``M`` segments has spine points ``c_k``, unit normals ``n_k`` and half-widths ``w_k``
(``k = 0..M``). Its strip mesh has a left rail ``L_k = c_k - w_k b_k`` and a right rail
``R_k = c_k + w_k b_k`` with ``b_k = normalize(n_k x t_k)``; UV ``(k/M, 0)`` on the left rail and
``(k/M, 1)`` on the right. Quad ``k`` is split into the triangles ``(L_k, R_k, L_k+1)`` and
``(R_k, R_k+1, L_k+1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _decoder, _writer
from .asset import Cards
from .parallel import map_blocks


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a0 b0 + a1 b1 + a2 b2`` of vectors ``[..., 3]``, in that order (spec 4, "Arithmetic")."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of vectors ``[..., 3]`` as the spec writes it (numpy's ``cross`` does not promise an order)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _normalize(v: np.ndarray) -> np.ndarray:
    """``v / max(|v|, 1e-30)`` (spec 4, "Arithmetic")."""
    return v / np.maximum(lengths(v), 1e-30)[..., None]


def lengths(v: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(v, axis=-1)`` of vectors ``[..., 3]``, the same numbers four times quicker."""
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])


def bounding_diagonal(points: np.ndarray) -> float:
    """The length of the diagonal of the bounding box of ``points [..., 3]`` (in float64), a coordinate
    at a time: reducing ``[N, 3]`` along its first axis takes numpy twenty times longer."""
    flat = points.reshape(-1, 3)
    lo = np.array([flat[:, k].min() for k in range(3)], np.float64)
    hi = np.array([flat[:, k].max() for k in range(3)], np.float64)
    return float(np.linalg.norm(hi - lo))


def arc_shares(points: np.ndarray) -> np.ndarray:
    """Each point's arc length along its strand as a share of the strand's, ``[N, P]`` for ``[N, P, 3]``."""
    total = np.cumsum(lengths(np.diff(np.asarray(points, np.float64), axis=1)), axis=1)
    total = np.concatenate([np.zeros((len(total), 1)), total], axis=1)
    return total / np.maximum(total[:, -1:], 1e-300)


def at_arc_shares(points: np.ndarray, shares: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Strands ``points [N, P, 3]`` whose points lie at the arc-length ``shares [N, P]`` (:func:`arc_shares`
    of their rest pose), interpolated along them at the shares ``wanted [N, Q]``: strands of different
    point counts compared point for point."""
    return np.stack([np.stack([np.interp(wanted[i], shares[i], points[i, :, c]) for c in range(3)], axis=-1)
                     for i in range(len(points))])


def spine_tangents(spine: np.ndarray) -> np.ndarray:
    """Unit tangents ``t_k`` of spines ``[C, M+1, 3]``: central differences, one-sided at the ends."""
    d = np.empty_like(spine)
    d[:, 1:-1] = spine[:, 2:] - spine[:, :-2]
    d[:, 0] = spine[:, 1] - spine[:, 0]
    d[:, -1] = spine[:, -1] - spine[:, -2]
    return _normalize(d)


def _reference_axis(t: np.ndarray) -> np.ndarray:
    """``normalize(e x t)`` for the unit axis ``e`` (x, y or z, the first on ties) least aligned
    with each ``t [..., 3]``."""
    e = np.eye(3)[np.argmin(np.abs(t), axis=-1)]
    return _normalize(cross(e, t))


def spine_frames(spine: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per spine point, the unit tangent ``t_k`` and a reference ``r_k`` across it, carried along the
    spine (spec 4.2): ``r_0`` from the axis least aligned with ``t_0``; ``r_k`` is ``r_(k-1)`` made
    perpendicular to ``t_k`` (the axis rule again where that leaves less than 1e-6). Float64."""
    t = spine_tangents(np.asarray(spine, np.float64))
    r = np.empty_like(t)
    r[:, 0] = _reference_axis(t[:, 0])
    for k in range(1, t.shape[1]):
        v = r[:, k - 1] - dot(r[:, k - 1], t[:, k])[:, None] * t[:, k]
        short = lengths(v) < 1e-6
        r[:, k] = np.where(short[:, None], _reference_axis(t[:, k]), _normalize(v))
    return t, r


def normal_angles(normal: np.ndarray, spine: np.ndarray, bits: int,
                  frames: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Card normals ``[C, M+1, 3]`` as angles about the spine (:func:`spine_frames`, or ``frames``, the
    spine's where the caller has them), in units of ``2 pi / 2^bits``, unwrapped along each card so that
    neighbouring angles differ by less than half a turn (the normals' component along the spine is
    dropped: the card builder's have none)."""
    t, r = spine_frames(spine) if frames is None else frames
    n = np.asarray(normal, np.float64)
    theta = np.arctan2(dot(n, cross(t, r)), dot(n, r))
    return np.unwrap(theta, axis=1) * (2**bits / (2 * np.pi))


def angle_normals(angle: np.ndarray, spine: np.ndarray, bits: int,
                  frames: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Inverse of :func:`normal_angles`: ``normalize(cos a r_k + sin a (t_k x r_k))``, ``a`` the angle
    ``angle / 2^bits`` of a turn (:func:`turn_cos_sin`), float64."""
    t, r = spine_frames(spine) if frames is None else frames
    c, s = turn_cos_sin(np.asarray(angle, np.float64) / 2.0**bits)
    return _normalize(c[..., None] * r + s[..., None] * cross(t, r))


TWO_PI = 6.283185307179586  # the float64 nearest 2 pi


def turn_cos_sin(turns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosine and sine of ``turns`` whole turns, as spec 4.2 defines them: on the nearest quarter turn's
    remainder (at most an eighth of a turn), Taylor polynomials to x^16 and x^17 (within 3e-18 of the
    true values there), in float64 operations only, so that every machine gets the same bits."""
    k = np.floor(4 * turns + 0.5)
    x = (turns - k / 4) * TWO_PI
    t = x * x
    c = np.ones_like(t)
    for n in range(16, 0, -2):
        c = 1 - (t / (n * (n - 1))) * c
    s = np.ones_like(t)
    for n in range(17, 1, -2):
        s = 1 - (t / (n * (n - 1))) * s
    s = x * s
    quarter = k - 4 * np.floor(k / 4)  # k mod 4
    cos = np.select([quarter == 0, quarter == 1, quarter == 2], [c, -s, -c], s)
    sin = np.select([quarter == 0, quarter == 1, quarter == 2], [s, c, -s], -c)
    return cos, sin


def card_bitangents(cards: Cards) -> np.ndarray:
    """Unit bitangents ``b_k = normalize(n_k x t_k)``, ``[C, M+1, 3]``, float64 from the float32 cards."""
    return _normalize(cross(cards.normal.astype(np.float64), spine_tangents(cards.spine.astype(np.float64))))


def card_rails(cards: Cards) -> np.ndarray:
    """The strips' rails ``[C, M+1, 2, 3]`` (``L_k``, ``R_k``; spec 5), float64."""
    b = card_bitangents(cards)
    p = cards.spine.astype(np.float64)
    w = cards.half_width.astype(np.float64)[..., None]
    return np.stack([p - w * b, p + w * b], axis=2)


@dataclass
class CardMesh:
    """The strip meshes of all cards, as one indexed triangle mesh."""

    vertices: np.ndarray  # [C * 2(M+1), 3] float32; card c, spine point k: left 2(c(M+1)+k), right +1
    normals: np.ndarray  # [C * 2(M+1), 3] float32
    uvs: np.ndarray  # [C * 2(M+1), 2] float32
    triangles: np.ndarray  # [C * 2M, 3] uint32
    card_of_triangle: np.ndarray  # [C * 2M] int32


def card_mesh(cards: Cards) -> CardMesh:
    """Derive the strip mesh (vertices, normals, UVs, triangles) of every card."""
    c, m1 = cards.spine.shape[:2]
    m = m1 - 1
    rails = card_rails(cards)
    normals = np.repeat(cards.normal[:, :, None, :], 2, axis=2)
    u = np.broadcast_to((np.arange(m1) / m)[None, :, None], (c, m1, 2))
    v = np.broadcast_to(np.array([0.0, 1.0])[None, None, :], (c, m1, 2))
    uvs = np.stack([u, v], axis=-1)
    base = (np.arange(c) * 2 * m1)[:, None] + 2 * np.arange(m)[None, :]  # index of L_k, [C, M]
    lk, rk, lk1, rk1 = base, base + 1, base + 2, base + 3
    tri = np.stack([np.stack([lk, rk, lk1], -1), np.stack([rk, rk1, lk1], -1)], axis=2)  # [C, M, 2, 3]
    return CardMesh(
        vertices=rails.reshape(-1, 3).astype(np.float32),
        normals=normals.reshape(-1, 3).astype(np.float32),
        uvs=uvs.reshape(-1, 2).astype(np.float32),
        triangles=tri.reshape(-1, 3).astype(np.uint32),
        card_of_triangle=np.repeat(np.arange(c, dtype=np.int32), 2 * m),
    )


def triangle_and_barycentrics(uv: np.ndarray, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Card triangle (``2k`` lower, ``2k+1`` upper) and barycentrics of card coordinates ``(u, v)``.

    ``uv`` is ``[..., 2]``. Barycentrics refer to the triangle's vertices in the order
    ``(L_k, R_k, L_k+1)`` or ``(R_k, R_k+1, L_k+1)``. Points outside the strip (``u`` outside
    [0, 1] or ``v`` outside [0, 1]) get the nearest segment and extrapolating barycentrics.
    """
    s = uv[..., 0] * segments
    k = np.clip(np.floor(s), 0, segments - 1)
    f = s - k
    v = uv[..., 1]
    upper = f + v > 1
    bary_lower = np.stack([1 - f - v, v, f], axis=-1)
    bary_upper = np.stack([1 - f, f + v - 1, 1 - v], axis=-1)
    bary = np.where(upper[..., None], bary_upper, bary_lower)
    return (2 * k + upper).astype(np.int64), bary


def card_scales(cards: Cards, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Per card, the world length of one unit of u and of v (upper bounds), at least ``step``."""
    m1 = cards.spine.shape[1]
    rails = card_rails(cards)
    seg = lengths(rails[:, 1:] - rails[:, :-1]).max(axis=(1, 2))
    su = np.maximum((m1 - 1) * seg, step)
    sv = np.maximum(2 * cards.half_width.astype(np.float64).max(axis=1), step)
    return su, sv


class CardMap:
    """The card-to-world mapping of section "Strand points", for many points.

    Each triangle is kept as the affine frame of spec 6.1: ``x = A + f * Ef + (v - upper) * Ev`` and
    likewise for the normal, where ``f`` is the fraction of the way along the quad and ``upper`` is 1
    on a quad's upper triangle; one gather per point fetches it. Float64 rails (:func:`card_rails`),
    the cards' float32 normals. The mapping itself, and its Jacobian, are compiled (:mod:`._decoder`).
    """

    def __init__(self, cards: Cards) -> None:
        triangles = card_mesh(cards).triangles
        self.segments = cards.segments
        v = card_rails(cards).reshape(-1, 3)[triangles]  # [T, 3 corners, 3]
        n = np.repeat(cards.normal.astype(np.float64), 2, axis=1).reshape(-1, 3)[triangles]
        upper = (np.arange(len(triangles)) % 2 == 1)[:, None]

        def frame(c):  # lower: d/df = c2 - c0, d/dv = c1 - c0; upper: d/df = c1 - c0, d/dv = c1 - c2
            return [c[:, 0], np.where(upper, c[:, 1], c[:, 2]) - c[:, 0],
                    np.where(upper, c[:, 1] - c[:, 2], c[:, 1] - c[:, 0])]

        self.frames = np.ascontiguousarray(np.concatenate(frame(v) + frame(n), axis=1))  # [T, 18]

    def __call__(self, card: np.ndarray, uvd: np.ndarray) -> np.ndarray:
        """World points ``[N, 3]`` (float64) of card coordinates ``uvd [N, 3]`` on cards ``card [N]``."""
        out = np.empty((len(card), 3))
        _decoder.map_points(self.frames, self.segments, np.ascontiguousarray(card, np.int64),
                           np.ascontiguousarray(uvd, np.float64), out)
        return out

    def strands(self, strand_card: np.ndarray, uvd: np.ndarray) -> np.ndarray:
        """World points ``[S, P, 3]`` (float64) of strands' card coordinates ``uvd [S, P, 3]``, by blocks
        of strands on every core."""
        s, p = uvd.shape[:2]
        out = np.empty((s, p, 3))

        def block(b: slice) -> None:
            card = np.repeat(np.asarray(strand_card[b], np.int64), p)
            out[b] = self(card, uvd[b].reshape(-1, 3).astype(np.float64)).reshape(-1, p, 3)

        map_blocks(block, s)
        return out

    def strand_points(self, strand_card: np.ndarray, uvd: np.ndarray) -> np.ndarray:
        """:meth:`strands` in float32 (``uvd`` float32 too), by blocks of strands on every core."""
        uvd = np.ascontiguousarray(uvd, np.float32)
        card = np.ascontiguousarray(strand_card, np.int64)
        out = np.empty(uvd.shape, np.float32)

        def block(b: slice) -> None:
            _decoder.map_strands(self.frames, self.segments, card[b], uvd[b], out[b])

        map_blocks(block, len(card))
        return out

    def invert(self, card: np.ndarray, uvd: np.ndarray, points: np.ndarray, steps: int = 4
               ) -> tuple[np.ndarray, np.ndarray]:
        """Card coordinates ``[N, 3]`` (float64) that map to ``points [N, 3]`` on cards ``card [N]``,
        and the distance ``[N]`` each is left from its point: Newton steps from ``uvd`` (a nearby guess,
        such as the coordinates on slightly other cards)."""
        out = np.array(uvd, np.float64, order="C")
        miss = np.empty(len(out))
        _writer.invert_points(self.frames, self.segments, np.ascontiguousarray(card, np.int64), out,
                              np.ascontiguousarray(points, np.float64), steps, miss)
        return out, miss


def strand_points(cards: Cards, strand_card: np.ndarray, uvd: np.ndarray) -> np.ndarray:
    """World positions ``[S, P, 3]`` of strand points given by card coordinates ``uvd [S, P, 3]``.

    ``x = sum_j beta_j V_j + delta * normalize(sum_j beta_j N_j)`` over the point's card triangle.
    """
    return CardMap(cards).strand_points(strand_card, uvd)
