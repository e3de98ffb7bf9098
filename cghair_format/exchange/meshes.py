"""Triangle meshes (a head or scalp to collide with): Wavefront OBJ, PLY and USD, read as plain arrays.

Only positions and faces are read; polygons are split into fans of triangles. OBJ and PLY state no
units (:attr:`TriangleMesh.meters_per_unit` is None: the caller takes them in its own); a USD stage gives
every ``Mesh`` prim in world space at its earliest time, with the stage's ``metersPerUnit`` and
``upAxis`` when authored. A mesh that is empty, holds NaN or infinite coordinates or indices out of
range, or exceeds :data:`MAX_TRIANGLES`, is refused in one line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._common import StrandFileError, read_bytes, readable_file

MESH_EXTENSIONS = (".obj", ".ply", ".usd", ".usda", ".usdc", ".usdz")
MAX_TRIANGLES = 4_000_000  # a head scan is well under; a collider's distance field needs no more


@dataclass(frozen=True)
class TriangleMesh:
    vertices: np.ndarray  # [V, 3] float64
    triangles: np.ndarray  # [T, 3] int64, indices into vertices
    meters_per_unit: float | None = None
    up_axis: str | None = None


def _fans(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Polygons given as ``counts [P]`` and flat ``indices`` split into triangles ``[T, 3]`` (fans)."""
    counts = np.asarray(counts, np.int64)
    if not len(counts):
        return np.zeros((0, 3), np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris = np.maximum(counts - 2, 0)
    first = np.repeat(starts, tris)
    corner = np.arange(int(tris.sum())) - np.repeat(np.cumsum(tris) - tris, tris)
    return np.stack([indices[first], indices[first + corner + 1], indices[first + corner + 2]], 1)


def _obj(path: Path) -> TriangleMesh:
    vertices, counts, indices = [], [], []
    for n, line in enumerate(read_bytes(path).decode("utf-8", "replace").splitlines(), start=1):
        parts = line.split()
        try:
            if parts and parts[0] == "v":
                vertices.append([float(v) for v in parts[1:4]])
            elif parts and parts[0] == "f":
                face = [int(p.split("/")[0]) for p in parts[1:]]
                indices.extend(i - 1 if i > 0 else len(vertices) + i for i in face)  # negatives count back
                counts.append(len(face))
        except ValueError:
            raise StrandFileError(path, f"OBJ line {n} is malformed: {line[:80]!r}") from None
        if len(counts) > MAX_TRIANGLES:
            raise StrandFileError(path, f"over {MAX_TRIANGLES:,} faces: decimate the collider mesh")
    if any(len(v) != 3 for v in vertices):
        raise StrandFileError(path, "an OBJ vertex line has fewer than three coordinates")
    triangles = _fans(np.array(counts, np.int64), np.array(indices, np.int64))
    return TriangleMesh(np.array(vertices, np.float64).reshape(-1, 3), triangles)


def _ply(path: Path) -> TriangleMesh:
    from ._ply import read_ply

    ply = read_ply(path)
    vertex, face = ply.elements.get("vertex"), ply.elements.get("face")
    if vertex is None or face is None or not {"x", "y", "z"} <= set(vertex.data):
        raise StrandFileError(path, "a PLY mesh needs a 'vertex' element with x, y, z and a 'face' element")
    lists = face.data.get("vertex_indices", face.data.get("vertex_index"))
    if lists is None:
        raise StrandFileError(path, "the PLY 'face' element has no 'vertex_indices' list")
    counts = np.array([len(f) for f in lists], np.int64)
    flat = np.concatenate(lists).astype(np.int64) if len(lists) else np.zeros(0, np.int64)
    points = np.stack([np.asarray(vertex.data[k], np.float64) for k in "xyz"], 1)
    return TriangleMesh(points, _fans(counts, flat))


def _usd(path: Path) -> TriangleMesh:
    from .usd_curves import _pxr, open_stage

    Usd, UsdGeom = _pxr()
    stage = open_stage(path)
    time = Usd.TimeCode.EarliestTime()
    cache = UsdGeom.XformCache(time)
    vertices, triangles, offset = [], [], 0
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        mesh = UsdGeom.Mesh(prim)
        points = np.asarray(mesh.GetPointsAttr().Get(time) or [], np.float64).reshape(-1, 3)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], np.int64)
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(time) or [], np.int64)
        if counts.sum() != len(indices) or (counts < 0).any():
            raise StrandFileError(path, f"{prim.GetPath()}: faceVertexCounts add up to {counts.sum()}, "
                                        f"faceVertexIndices has {len(indices)}")
        world = np.array(cache.GetLocalToWorldTransform(prim), np.float64)  # row vectors
        vertices.append(points @ world[:3, :3] + world[3, :3])
        triangles.append(_fans(counts, indices) + offset)
        offset += len(points)
    if not vertices:
        raise StrandFileError(path, "the USD stage has no Mesh prim")
    kw = {}
    if UsdGeom.StageHasAuthoredMetersPerUnit(stage):
        kw["meters_per_unit"] = float(UsdGeom.GetStageMetersPerUnit(stage))
    if stage.HasAuthoredMetadata("upAxis"):
        kw["up_axis"] = str(UsdGeom.GetStageUpAxis(stage))
    return TriangleMesh(np.concatenate(vertices), np.concatenate(triangles), **kw)


def check_mesh(path: str | Path, mesh: TriangleMesh) -> TriangleMesh:
    """``mesh``, or a one-line :class:`StrandFileError` saying what makes it unusable."""
    v, t = mesh.vertices, mesh.triangles
    if len(t) == 0 or len(v) == 0:
        raise StrandFileError(path, f"the mesh is empty ({len(v)} vertices, {len(t)} triangles)")
    if len(t) > MAX_TRIANGLES:
        raise StrandFileError(path, f"{len(t):,} triangles, over {MAX_TRIANGLES:,}: decimate the collider mesh")
    if not np.isfinite(v).all():
        raise StrandFileError(path, f"vertex {int(np.argmax(~np.isfinite(v).all(1)))} holds NaN or infinite values")
    if t.min() < 0 or t.max() >= len(v):
        raise StrandFileError(path, f"a face refers to vertex {int(t.max() if t.max() >= len(v) else t.min())}, "
                                    f"outside the mesh's 0..{len(v) - 1}")
    return mesh


def load_mesh(path: str | Path) -> TriangleMesh:
    """The triangles of an ``.obj``, ``.ply`` or USD file, checked (:func:`check_mesh`)."""
    p, ext = readable_file(path, MESH_EXTENSIONS, "a mesh")
    reader = _obj if ext == ".obj" else _ply if ext == ".ply" else _usd
    return check_mesh(path, reader(p))
