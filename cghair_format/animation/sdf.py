"""A signed distance field of a head mesh, as TressFX 4 collides hair with one: built once on a regular
grid in the head's rest frame, sampled trilinearly wherever the head has moved to.

Near the surface (within :data:`BAND` cells of a triangle) each node holds its exact distance to the
nearest triangle, signed by that triangle's angle-weighted pseudo-normal at the nearest feature (face,
edge or vertex; Baerentzen and Aanaes 2005): the sign is right for closed meshes and tells the two sides
of an open scalp cap apart near it, where collisions happen. Farther nodes take the sign of the nearest
band node (found by scipy's exact Euclidean distance transform) and the distance to that node's nearest
point on the mesh: close to exact, and it keeps the gradient pointing out of the head.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CghError, require

BAND = 2  # cells around each triangle where the distance is exact
RESOLUTION = 64  # nodes along the longest side of the grid
MAX_RESOLUTION = 256  # 16.7 million nodes: some 3 GB of arrays while the field is built
PAIRS_PER_CHUNK = 1 << 18  # (triangle, node) pairs evaluated at once: bounds the memory of a build


@dataclass(frozen=True)
class DistanceField:
    """Signed distance (negative inside) at the nodes ``origin + cell * (i, j, k)``, and its gradient."""

    distance: np.ndarray  # [X, Y, Z] float64
    gradient: np.ndarray  # [X, Y, Z, 3] float64
    origin: np.ndarray  # [3]
    cell: float
    margin: float = 0.0  # points closer to the surface than this (scene units) are pushed out too

    def __post_init__(self) -> None:
        # distance and gradient side by side, one row a node: a sample gathers 8 rows, not 16 scattered values
        packed = np.concatenate([self.distance[..., None], self.gradient], -1).reshape(-1, 4)
        object.__setattr__(self, "_packed", np.ascontiguousarray(packed))

    def sample(self, points: np.ndarray, within: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The distance ``[...]`` and gradient ``[..., 3]`` at ``points [..., 3]`` (trilinear); points off
        the grid are infinitely far (nothing to collide with there), and so are those whose nearest node
        shows them farther than ``within`` (given): most of a groom, which then costs one lookup a point."""
        shape = np.array(self.distance.shape)
        u = (np.asarray(points, np.float64) - self.origin) / self.cell
        flat_u = u.reshape(-1, 3)
        distance, gradient = np.full(len(flat_u), np.inf), np.zeros((len(flat_u), 3))
        strides = np.array([shape[1] * shape[2], shape[2], 1])
        on = np.flatnonzero(((flat_u >= 0) & (flat_u <= shape - 1)).all(-1))
        if within is not None:  # the interpolated distance is within a cell diagonal of the nearest node's
            nearest = self._packed[np.rint(flat_u[on]).astype(np.int64) @ strides, 0]
            on = on[nearest - np.sqrt(3.0) * self.cell < within]
        i = np.clip(np.floor(flat_u[on]).astype(np.int64), 0, shape - 2)
        w = np.clip(flat_u[on] - i, 0.0, 1.0)
        weights = np.stack([1.0 - w, w])  # [2, K, 3]: the weight of the lower and upper node on each axis
        base = i @ strides
        out = np.zeros((len(on), 4))
        for a in (0, 1):
            for b in (0, 1):
                for c in (0, 1):
                    weight = weights[a, :, 0] * weights[b, :, 1] * weights[c, :, 2]
                    out += weight[:, None] * self._packed[base + (a * strides[0] + b * strides[1] + c)]
        distance[on], gradient[on] = out[:, 0], out[:, 1:]
        return distance.reshape(u.shape[:-1]), gradient.reshape(u.shape)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def pseudo_normals(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit face normals ``[T, 3]``, edge normals ``[T, 3 edges, 3]`` (the sum of the faces sharing each edge
    ``ab, bc, ca``) and angle-weighted vertex normals ``[V, 3]``."""
    p = vertices[triangles]  # [T, 3 corners, 3]
    face = _unit(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
    vertex = np.zeros_like(vertices)
    for c in range(3):
        e1, e2 = _unit(p[:, (c + 1) % 3] - p[:, c]), _unit(p[:, (c + 2) % 3] - p[:, c])
        angle = np.arccos(np.clip((e1 * e2).sum(-1), -1.0, 1.0))
        np.add.at(vertex, triangles[:, c], angle[:, None] * face)
    ends = np.stack([triangles, np.roll(triangles, -1, axis=1)], -1).reshape(-1, 2)  # [T*3, 2]
    _, key = np.unique(np.sort(ends, 1), axis=0, return_inverse=True)
    key = key.reshape(-1)
    edge_sum = np.zeros((int(key.max()) + 1, 3))
    np.add.at(edge_sum, key, np.repeat(face, 3, axis=0))
    return face, edge_sum[key].reshape(-1, 3, 3), vertex


def _closest(q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For points ``q [K, 3]`` and triangles ``p [K, 3, 3]``: the closest point, the feature holding it
    (0: the face, 1..3: edge ab, bc, ca inside, 4..6: vertex a, b, c) and the distance."""
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    nn = (n * n).sum(-1)
    plane = q - n * (((q - p[:, 0]) * n).sum(-1) / np.maximum(nn, 1e-300))[:, None]
    inside = nn > 0
    for c in range(3):  # the projection lies on the inner side of every edge
        edge = p[:, (c + 1) % 3] - p[:, c]
        inside &= (np.cross(edge, plane - p[:, c]) * n).sum(-1) >= 0
    best = np.where(inside[:, None], plane, 0.0)
    best_sq = np.where(inside, ((q - plane) ** 2).sum(-1), np.inf)
    feature = np.zeros(len(q), np.int64)
    for c in range(3):
        a, ab = p[:, c], p[:, (c + 1) % 3] - p[:, c]
        t = np.clip(((q - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0.0, 1.0)
        point = a + t[:, None] * ab
        sq = ((q - point) ** 2).sum(-1)
        better = sq < best_sq
        best = np.where(better[:, None], point, best)
        best_sq = np.where(better, sq, best_sq)
        kind = np.where(t <= 0, 4 + c, np.where(t >= 1, 4 + (c + 1) % 3, 1 + c))
        feature = np.where(better, kind, feature)
    return best, feature, np.sqrt(best_sq)


def _pairs(lo: np.ndarray, hi: np.ndarray, shape: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (triangle, flat node) pair of the node boxes ``lo..hi [K, 3]`` (inclusive), and the node's
    ``(i, j, k)``."""
    span = hi - lo + 1
    count = span.prod(1)
    tri = np.repeat(np.arange(len(lo)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    sy, sz = span[tri, 1], span[tri, 2]
    ijk = lo[tri] + np.stack([k // (sy * sz), (k // sz) % sy, k % sz], 1)
    return tri, np.ravel_multi_index(ijk.T, tuple(shape)), ijk


def _band(vertices, triangles, origin, cell, shape) -> tuple[np.ndarray, np.ndarray]:
    """Exact signed distances ``[X*Y*Z]`` (NaN off the band) at the nodes within :data:`BAND` cells of a
    triangle, and each one's nearest point on the mesh ``[X*Y*Z, 3]``."""
    face, edge, vertex = pseudo_normals(vertices, triangles)
    p = vertices[triangles]
    band = BAND * cell
    centre = p.mean(1)
    reach = np.sqrt(((p - centre[:, None]) ** 2).sum(-1).max(1)) + band
    lo = np.clip(np.floor((p.min(1) - origin) / cell).astype(np.int64) - BAND, 0, shape - 1)
    hi = np.clip(np.ceil((p.max(1) - origin) / cell).astype(np.int64) + BAND, 0, shape - 1)
    keep = (p.max(1) >= origin - BAND * cell).all(1) & (p.min(1) <= origin + (shape - 1 + BAND) * cell).all(1)
    tris = np.flatnonzero(keep)
    dist = np.full(int(shape.prod()), np.inf)
    sign = np.ones(int(shape.prod()))
    nearest = np.zeros((int(shape.prod()), 3))
    total = np.cumsum((hi[tris] - lo[tris] + 1).prod(1))
    cuts = np.searchsorted(total, np.arange(PAIRS_PER_CHUNK, total[-1] if len(total) else 0, PAIRS_PER_CHUNK))
    for chunk in np.split(tris, np.unique(cuts)):
        if not len(chunk):
            continue
        t_local, node, ijk = _pairs(lo[chunk], hi[chunk], shape)
        t = chunk[t_local]
        q = origin + cell * ijk
        # cheap tests first: only nodes within the band of the triangle's bounding sphere and of its plane
        near = (((q - centre[t]) ** 2).sum(-1) <= reach[t] ** 2) & (np.abs(((q - p[t, 0]) * face[t]).sum(-1)) <= band)
        t, node, q = t[near], node[near], q[near]
        point, feature, d = _closest(q, p[t])
        within = d <= band  # a node farther from its nearest triangle may have met only farther ones here
        t, node, q, point, feature, d = t[within], node[within], q[within], point[within], feature[within], d[within]
        corner = triangles[t, np.clip(feature - 4, 0, 2)]
        normal = np.where((feature == 0)[:, None], face[t],
                          np.where((feature >= 4)[:, None], vertex[corner], edge[t, np.clip(feature - 1, 0, 2)]))
        s = np.where(((q - point) * normal).sum(-1) < 0, -1.0, 1.0)
        order = np.lexsort((d, node))  # the nearest triangle first for each node
        keep = order[np.r_[True, node[order][1:] != node[order][:-1]]]
        node, d, s, point = node[keep], d[keep], s[keep], point[keep]
        closer = d < dist[node]
        dist[node[closer]], sign[node[closer]], nearest[node[closer]] = d[closer], s[closer], point[closer]
    return np.where(np.isfinite(dist), dist * sign, np.nan), nearest


def mesh_field(vertices: np.ndarray, triangles: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               resolution: int = RESOLUTION, margin: float = 0.0) -> DistanceField:
    """The signed distance field of the mesh (``vertices [V, 3]``, ``triangles [T, 3]``) on a grid of cubic
    cells over the box ``lo..hi``, ``resolution`` nodes along its longest side."""
    ndimage = require("scipy.ndimage", "cards", "the collider's distance field", package="scipy")
    v, t = np.asarray(vertices, np.float64), np.asarray(triangles, np.int64)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if not (hi > lo).all() or not 4 <= resolution <= MAX_RESOLUTION:
        raise CghError(f"a distance field needs a box with hi > lo and 4..{MAX_RESOLUTION} nodes a side, got "
                       f"{lo}..{hi} and {resolution}")
    cell = float((hi - lo).max()) / (resolution - 1)
    shape = np.maximum(np.ceil((hi - lo) / cell).astype(np.int64) + 1, 2)
    signed, surface = _band(v, t, lo, cell, shape)
    known = np.isfinite(signed)
    if not known.any():
        raise CghError("the collider mesh does not reach the grid around the hair: give it in the groom's units "
                       "and frame")
    grid = signed.reshape(tuple(shape))
    seed = np.ravel_multi_index(ndimage.distance_transform_edt(
        ~known.reshape(tuple(shape)), return_distances=False, return_indices=True), tuple(shape))
    nodes = lo + cell * np.stack(np.indices(tuple(shape)), -1)
    far = np.linalg.norm(nodes - surface[seed], axis=-1)  # to the nearest band node's nearest mesh point
    distance = np.where(known.reshape(tuple(shape)), grid, np.where(signed[seed] < 0, -far, far))
    gradient = np.stack(np.gradient(distance, cell), -1)
    return DistanceField(distance, gradient, lo, cell, float(margin))


def hair_box(points: np.ndarray, mesh_vertices: np.ndarray, pad: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """The box a collider's field covers: the hair's bounding box grown by ``pad`` of its diagonal (the
    hair swings out of its rest box), cut to the mesh's box grown by a tenth of its own diagonal (nothing
    to collide with beyond); a :class:`CghError` when the two do not meet (a mesh in other units or frame)."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    p_lo, p_hi = pts.min(0), pts.max(0)
    m_lo, m_hi = mesh_vertices.min(0), mesh_vertices.max(0)
    grow, m_grow = pad * np.linalg.norm(p_hi - p_lo), 0.1 * np.linalg.norm(m_hi - m_lo)
    lo, hi = np.maximum(p_lo - grow, m_lo - m_grow), np.minimum(p_hi + grow, m_hi + m_grow)
    if not (hi > lo).all():
        raise CghError(f"the collider mesh ({m_lo.round(3)}..{m_hi.round(3)}) lies nowhere near the hair "
                       f"({p_lo.round(3)}..{p_hi.round(3)}): give it in the groom's units and frame")
    return lo, hi
