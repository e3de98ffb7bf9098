"""Strand growth: from each root, steps along the 3D orientation field while inside the hair volume.

At each step the field's tensor ``c d d^T`` is interpolated at the tip and one power-iteration step
from the previous direction gives the new one: it follows the field's dominant direction, keeps the
strand's sense (the field has none), and, where the field is weak, keeps going straight. A strand
stops where it leaves the hull or reaches ``max_length``.

The visual hull is larger than the hair: the masks are closed and dilated, the rendered strands have
a width, and a voxel is kept when its centre projects into a mask pixel. Growth therefore keeps
``inset`` (world units; the pipeline passes a few pixel footprints) inside the hull's boundary,
except near roots outside that core (a given scalp may place a thin hairline on the boundary).
"""

from __future__ import annotations

import numpy as np

from cghair_format.strands import Strands, resample

from .hull import Hull, trilinear
from .scalp import Roots

STEP = 0.5  # voxels per growth step
INERTIA = 0.2  # weight of the previous direction against the field: damps kinks from noisy voxels
MIN_POINTS = 4  # shorter strands (in steps) are dropped
LIFT = 0.3
SLIDE_MAX = np.radians(60.0)
NUDGE = 0.2  # a sliding strand also steps this much inward, to stay off the boundary
LOOKAHEAD = 2  # voxels
BOTTOM_COS = 0.5  # a boundary whose inward normal is within 60 degrees of up is a bottom
GRACE = 4.0  # voxels a root outside the hull may travel to reach it
INSIDE_LEVEL = 0.25  # interpolated occupancy above which a point is in the hull (a quarter voxel out)


def _ahead_inside(occ: np.ndarray, hull: Hull, points: np.ndarray, d: np.ndarray) -> np.ndarray:
    """In the hull at ``points`` or within ``LOOKAHEAD`` voxels ahead along ``d``: a strand crosses
    the small gaps that sparse masks carve into the hull."""
    inside = np.zeros(len(points), bool)
    for k in range(LOOKAHEAD + 1):
        inside |= trilinear(occ, hull.grid.to_index(points + k * hull.grid.voxel * d)) > INSIDE_LEVEL
    return inside


def initial_directions(roots: Roots, up: np.ndarray) -> np.ndarray:
    """Hair leaves the scalp downhill, close to the surface: gravity projected on the scalp's tangent
    plane, lifted by ``LIFT`` times the normal (straight out where the scalp faces up)."""
    n = roots.normals / np.linalg.norm(roots.normals, axis=1, keepdims=True)
    down = -np.asarray(up, np.float64)
    tangent = down - (n @ down)[:, None] * n
    d = tangent + LIFT * n
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)


def growth_volume(hull: Hull, roots: Roots, inset: float) -> np.ndarray:
    """The hull less its outer ``inset``, plus the hull within ``inset + GRACE`` voxels of the roots
    that lie outside that core."""
    from scipy.ndimage import distance_transform_edt

    depth = distance_transform_edt(hull.occupancy) * hull.grid.voxel
    core = depth > inset
    if inset <= 0:
        return core
    seeds = np.ones(hull.grid.shape, bool)
    idx = np.round(hull.grid.to_index(roots.points)).astype(int)
    ok = ((idx >= 0) & (idx < np.array(hull.grid.shape))).all(1)
    idx = idx[ok]
    seeds[tuple(idx[~core[tuple(idx.T)]].T)] = False  # only roots the core leaves out get a band
    if seeds.all():  # (the transform of an array without zeros is not a distance)
        return core
    near_root = distance_transform_edt(seeds) * hull.grid.voxel <= inset + GRACE * hull.grid.voxel
    return core | (hull.occupancy & near_root)


def grow_strands(hull: Hull, roots: Roots, up: np.ndarray, points_per_strand: int = 32,
                 max_length: float | None = None, meters_per_unit: float = 1.0, up_axis: str = "Y",
                 inset: float = 0.0) -> Strands:
    """Grow from ``roots`` inside :func:`growth_volume`; returns strands resampled to
    ``points_per_strand`` points."""
    h = STEP * hull.grid.voxel
    up = np.asarray(up, np.float64) / np.linalg.norm(up)
    if max_length is None:
        max_length = float(np.linalg.norm(np.array(hull.grid.shape) * hull.grid.voxel))
    n_steps = int(max_length / h)
    from scipy.ndimage import gaussian_filter

    occ = growth_volume(hull, roots, inset).astype(np.float32)
    inward = np.stack(np.gradient(gaussian_filter(occ, 1.5)), -1)  # towards the inside of the hull
    pos = roots.points.copy()
    prev = initial_directions(roots, up)
    path = [pos.copy()]
    alive = np.ones(len(pos), bool)
    entered = np.zeros(len(pos), bool)
    lengths = np.ones(len(pos), int)
    for _ in range(n_steps):
        if not alive.any():
            break
        a = np.flatnonzero(alive)
        coords = hull.grid.to_index(pos[a])
        t = trilinear(hull.field, coords)  # [n, 3, 3]
        d = np.einsum("nij,nj->ni", t, prev[a]) + INERTIA * prev[a] * np.trace(t, axis1=1, axis2=2)[:, None]
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.where(norm > 1e-9, d / np.maximum(norm, 1e-12), prev[a])
        new = pos[a] + h * d
        inside = _ahead_inside(occ, hull, new, d)
        # at the boundary, slide along it unless that turns the strand by more than SLIDE_MAX
        out = np.flatnonzero(~inside)
        if len(out):
            g = trilinear(inward, hull.grid.to_index(pos[a[out]]))
            g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
            slid = d[out] + (np.maximum(0.0, -np.einsum("ij,ij->i", d[out], g)) + NUDGE)[:, None] * g
            kept = np.linalg.norm(slid, axis=1)
            slid /= np.maximum(kept, 1e-12)[:, None]
            cand = pos[a[out]] + h * slid
            # no sliding along a bottom (the inside above): hair ends there, it does not crawl
            ok = (kept > np.cos(SLIDE_MAX)) & (g @ up < BOTTOM_COS) & _ahead_inside(occ, hull, cand, slid)
            d[out[ok]], new[out[ok]], inside[out[ok]] = slid[ok], cand[ok], True
        # a root off the hull (a given scalp where the masks carved the hairline) gets GRACE voxels
        # to reach in; a strand stops when it leaves the hull after having been inside
        entered[a] |= inside
        stop = (~inside & entered[a]) | (~entered[a] & (lengths[a] > GRACE / STEP))
        go = a[~stop]
        pos[go], prev[go] = new[~stop], d[~stop]
        lengths[go] += 1
        alive[a[stop]] = False
        step_pts = pos.copy()
        path.append(step_pts)
    path = np.stack(path, 1)  # [R, T, 3]; a stopped strand repeats its last point
    keep = (lengths >= MIN_POINTS) & entered
    offsets = np.concatenate([[0], np.cumsum(lengths[keep])])
    flat = np.concatenate([path[i, :lengths[i]] for i in np.flatnonzero(keep)]) if keep.any() else np.zeros((0, 3))
    s = Strands(flat.astype(np.float32), offsets.astype(np.int64), meters_per_unit=meters_per_unit, up_axis=up_axis)
    return resample(s, points_per_strand) if s.count else s
