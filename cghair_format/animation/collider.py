"""A head mesh as the solver's collider: read (:mod:`cghair_format.exchange.meshes`), brought to the
asset's units and axes, and made a :class:`~.sdf.DistanceField` over the hair once, in the head's rest
frame (the pose the .cgh holds), which the solver's :func:`~.solver.collide_field` samples wherever the
head has moved to.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..exchange.meshes import TriangleMesh, load_mesh
from .sdf import RESOLUTION, DistanceField, hair_box, mesh_field
from .track_file import file_axes

MARGIN_M = 1e-3  # hair is pushed to 1 mm off the mesh: a little over a strand's thickness, under a cell


def mesh_in_asset(mesh: TriangleMesh, asset) -> np.ndarray:
    """The mesh's vertices ``[V, 3]`` in the asset's units (the file's ``metersPerUnit`` when it states one,
    else the asset's own) and up axis (when the file states one)."""
    scale = 1.0 if mesh.meters_per_unit is None else mesh.meters_per_unit / asset.meters_per_unit
    return (mesh.vertices * scale) @ file_axes(mesh.up_axis, asset.up_axis).T


def collider_field(asset, mesh: TriangleMesh | str | Path, resolution: int = RESOLUTION,
                   margin: float | None = None) -> DistanceField:
    """The distance field of the head ``mesh`` (a :class:`TriangleMesh` or a file) around ``asset``'s
    cards, ``resolution`` nodes along the grid's longest side; points are kept ``margin`` scene units off it
    (default :data:`MARGIN_M`)."""
    if not isinstance(mesh, TriangleMesh):
        mesh = load_mesh(mesh)
    vertices = mesh_in_asset(mesh, asset)
    lo, hi = hair_box(asset.cards.spine, vertices)
    margin = MARGIN_M / asset.meters_per_unit if margin is None else margin
    return mesh_field(vertices, mesh.triangles, lo, hi, resolution, margin)


def depth_inside(field: DistanceField, points: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> float:
    """How deep the deepest of ``points [..., 3]`` lies inside the mesh (scene units, 0 when none does),
    with the head at ``x -> rotation x + translation``."""
    local = (np.asarray(points, np.float64).reshape(-1, 3) - translation) @ rotation
    distance, _ = field.sample(local, within=0.0)
    return float(max(0.0, -distance.min())) if len(distance) else 0.0
