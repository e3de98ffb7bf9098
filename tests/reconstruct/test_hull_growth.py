"""The visual hull, the triangulated 3D orientation field and growth on a capture of parallel
strands whose direction is known."""

import numpy as np
import pytest

from cghair_format.strands import Strands
from training.dataset import render_dataset
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
