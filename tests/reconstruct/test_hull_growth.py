"""The visual hull, the triangulated 3D orientation field and growth on a capture of parallel
strands whose direction is known."""

import numpy as np
import pytest

from cghair_format.strands import Strands
from training.datasets.synthetic import render_dataset
from training.reconstruct.grow import grow_strands
from training.reconstruct.hull import orientation_field, visual_hull
from training.reconstruct.orientation import orientation_map
from training.reconstruct.scalp import Roots

DIRECTION = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    """400 straight strands 0.2 long along DIRECTION, roots on a 0.1 x 0.1 square."""
    rng = np.random.default_rng(0)
    roots = np.stack([rng.uniform(-0.05, 0.05, 400), np.zeros(400), rng.uniform(-0.05, 0.05, 400)], 1)
    t = np.linspace(0, 0.2, 24)
    pts = roots[:, None] + t[None, :, None] * DIRECTION
    strands = Strands.from_array(pts.astype(np.float32))
    ds = render_dataset(strands, tmp_path_factory.mktemp("block"), views=24, res=96)
    return strands, ds


@pytest.mark.slow
def test_field_recovers_the_known_direction_and_growth_follows_it(block):
    strands, ds = block
    views = ds.train
    hull = visual_hull(views, resolution=40)
    # the hull holds every strand point (it may hold more: it is an outer bound)
    inside = hull.occupancy[tuple(np.round(hull.grid.to_index(strands.points)).astype(int).clip(
        0, np.array(hull.grid.shape) - 1).T)]
    assert inside.mean() > 0.97
    hull = orientation_field(hull, views, [orientation_map(v.image) for v in views])
    f = hull.field[hull.occupancy]
    strong = np.trace(f, axis1=1, axis2=2) > 0.2
    d = np.linalg.eigh(f[strong])[1][:, :, -1]
    err = np.degrees(np.arccos(np.clip(np.abs(d @ DIRECTION), 0, 1)))
    print(f"{strong.sum()} voxels: median {np.median(err):.1f} deg, 90th percentile {np.percentile(err, 90):.1f}")
    assert np.median(err) < 10.0
    # grown from the true roots with an upward normal, the strands follow DIRECTION, not the normal
    roots = Roots(strands.to_array()[::8, 0].astype(np.float64), np.tile([0.0, 1.0, 0.0], (50, 1)))
    grown = grow_strands(hull, roots, np.array([0.0, 1.0, 0.0]), 16)
    seg = np.diff(grown.to_array(), axis=1).reshape(-1, 3)
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    assert np.median(np.degrees(np.arccos(np.clip(np.abs(seg @ DIRECTION), 0, 1)))) < 15.0
    length = np.linalg.norm(np.diff(grown.to_array(), axis=1), axis=2).sum(1)
    assert 0.1 < np.median(length) < 0.3


def test_growth_keeps_the_inset_inside_the_hull_away_from_the_roots():
    """Strands slanting into a wall of a box hull slide along it: at ``inset`` 0 on the boundary
    layer, at ``inset`` 3 voxels at least that deep, except near the roots on the box's top."""
    from scipy.ndimage import distance_transform_edt
    from scipy.spatial import cKDTree

    from training.reconstruct.grow import GRACE, growth_volume
    from training.reconstruct.hull import Grid, Hull

    occ = np.zeros((30, 40, 30), bool)
    occ[5:25, 5:35, 5:25] = True
    d = np.array([0.6, -1.0, 0.0]) / np.linalg.norm([0.6, -1.0, 0.0])
    field = np.where(occ[..., None, None], np.outer(d, d), 0.0).astype(np.float32)
    hull = Hull(Grid(np.zeros(3), 1.0, occ.shape), occ, field)
    xz = np.stack(np.meshgrid(np.arange(7, 23, 2.0), np.arange(7, 23, 2.0)), -1).reshape(-1, 2)
    roots = Roots(np.stack([xz[:, 0], np.full(len(xz), 34.0), xz[:, 1]], 1), np.tile([0.0, 1.0, 0.0], (len(xz), 1)))
    depth = distance_transform_edt(occ)
    near_root = GRACE + 4.0  # voxels: the band around the roots where the inset does not apply

    def depths(inset):
        s = grow_strands(hull, roots, np.array([0.0, 1.0, 0.0]), 64, inset=inset)
        pts = s.points[cKDTree(roots.points).query(s.points)[0] > near_root]
        return s.count, depth[tuple(np.round(pts).astype(int).T)]

    n0, d0 = depths(0.0)
    n3, d3 = depths(3.0)
    assert n3 >= n0 > len(xz) // 2  # the inset drops no strand
    assert (d0 < 3).mean() > 0.05  # without it, strands run along the wall in its outer layers
    assert (d3 >= 3).all()
    # roots inside the core get no band: the volume is the core alone
    deep = Roots(np.array([[15.0, 20.0, 15.0]]), np.array([[0.0, 1.0, 0.0]]))
    assert (growth_volume(hull, deep, 3.0) == (depth > 3)).all()
