"""The scalp the strands grow from: a given mesh (OBJ, PLY, ... read by trimesh) or, without one,
an estimate from the visual hull; and root positions with outward normals sampled on it.

The estimate takes the hull's boundary voxels that face up (normal within 60 degrees of the up
axis, where a head's hair parts and crown are) and moves them ``depth`` voxels inward: a cap under
the top layer of the hair. It knows no head; a given mesh is better wherever one exists.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .hull import Hull, ReconstructError, trilinear

UP_COS = 0.5  # estimated scalp: boundary normals within 60 degrees of up
ESTIMATE_DEPTH = 2.0  # voxels inward from the hull boundary
MIN_INSIDE = 0.5  # a given scalp with fewer roots than this inside the (dilated) hull is refused


@dataclass
class Roots:
    points: np.ndarray  # [R, 3]
    normals: np.ndarray  # [R, 3] unit, away from the head


def load_scalp_mesh(path: str | Path):
    """A triangle mesh, refusing files that are empty or not a usable surface."""
    try:
        import trimesh
    except ImportError:
        raise ReconstructError("reading a scalp mesh needs trimesh: pip install 'cghair[reconstruct]'") from None
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(p))
    try:
        mesh = trimesh.load(p, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        raise ReconstructError(f"scalp mesh {p}: cannot read it ({type(exc).__name__}: {exc})") from None
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))))
    verts = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), np.float64)
    if len(faces) == 0 or len(verts) == 0:
        raise ReconstructError(f"scalp mesh {p}: no triangles")
    if not np.isfinite(verts).all():
        raise ReconstructError(f"scalp mesh {p}: vertices contain NaN or infinite values")
    if faces.min() < 0 or faces.max() >= len(verts):
        raise ReconstructError(f"scalp mesh {p}: faces refer to vertices that do not exist")
    if not float(mesh.area) > 0:
        raise ReconstructError(f"scalp mesh {p}: its triangles have no area")
    return mesh


def sample_mesh_roots(mesh, n: int, seed: int = 0) -> Roots:
    """``n`` roots spread evenly by area; normals point away from the mesh's centroid side."""
    import trimesh

    pts, face = trimesh.sample.sample_surface_even(mesh, n, seed=seed)
    if len(pts) < n:  # even sampling can return fewer; top up by area
        extra, f2 = trimesh.sample.sample_surface(mesh, n - len(pts), seed=seed)
        pts, face = np.concatenate([pts, extra]), np.concatenate([face, f2])
    normals = np.asarray(mesh.face_normals)[face]
    centre = np.asarray(mesh.vertices).mean(0)
    # a cap's centroid lies below it: orient every normal away from the centroid, whatever the winding
    flip = np.einsum("ij,ij->i", normals, pts - centre) < 0
    normals = np.where(flip[:, None], -normals, normals)
    return Roots(np.asarray(pts, np.float64), normals)


def check_roots_in_hull(roots: Roots, hull: Hull, source: str) -> None:
    from scipy.ndimage import binary_dilation

    near = binary_dilation(hull.occupancy, iterations=3).astype(np.float32)
    inside = trilinear(near, hull.grid.to_index(roots.points)) > 0.5
    if inside.mean() < MIN_INSIDE:
        raise ReconstructError(f"{source}: only {inside.mean():.0%} of its roots lie in the hair volume the views "
                               "see; the scalp and the cameras are not in the same frame or scale")


def estimate_scalp(hull: Hull, up: np.ndarray, n: int, seed: int = 0, depth: float = ESTIMATE_DEPTH) -> Roots:
    """Roots on the estimated cap (see the module docstring), ``n`` of them, jittered within a voxel."""
    from scipy.ndimage import binary_erosion, gaussian_filter

    occ = hull.occupancy
    boundary = occ & ~binary_erosion(occ)
    smooth = gaussian_filter(occ.astype(np.float32), 1.5)
    grad = np.stack(np.gradient(smooth), -1)  # points inward (towards higher occupancy)
    idx = np.argwhere(boundary)
    g = grad[tuple(idx.T)]
    normal = -g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-9)
    cap = normal @ up > UP_COS
    if not cap.any():
        raise ReconstructError("cannot estimate a scalp: the hair volume has no upward-facing surface; "
                               "pass --scalp MESH")
    rng = np.random.default_rng(seed)
    pick = rng.choice(np.flatnonzero(cap), n, replace=cap.sum() < n)
    centres = hull.grid.origin + idx[pick] * hull.grid.voxel
    jitter = (rng.random((n, 3)) - 0.5) * hull.grid.voxel
    pts = centres + jitter - normal[pick] * depth * hull.grid.voxel
    return Roots(pts, normal[pick])
