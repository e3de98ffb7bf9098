"""Known heads for the track and collider tests: a USD stage with an animated head transform, and a
sphere mesh (closed, or cut to an open scalp cap) written as OBJ or PLY."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_xform_track(path: Path, rotation: np.ndarray, translation: np.ndarray, fps: float = 24.0, *,
                      first_code: float = 1.0, codes: list[float] | None = None, meters_per_unit: float = 1.0,
                      up_axis: str = "Y", prim: str = "/rig/head", scale: float = 1.0, parent_offset=None,
                      others: tuple[str, ...] = ()) -> None:
    """A USD stage whose ``prim`` is moved by ``x -> scale * rotation[f] x + translation[f]`` (column
    vectors) at time code ``first_code + f``, under a parent translated by ``parent_offset``; each of
    ``others`` is one more prim with an animated translation."""
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up_axis)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(fps)
    codes = codes or [first_code + f for f in range(len(rotation))]
    parent = UsdGeom.Xform.Define(stage, str(Path(prim).parent))
    if parent_offset is not None:
        parent.AddTranslateOp().Set(Gf.Vec3d(*map(float, parent_offset)))
    op = UsdGeom.Xform.Define(stage, prim).AddTransformOp()
    for code, r, t in zip(codes, rotation, translation, strict=True):
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = scale * r, t
        op.Set(Gf.Matrix4d(m.T.tolist()), Usd.TimeCode(code))  # USD's matrices act on row vectors
    for other in others:
        move = UsdGeom.Xform.Define(stage, other).AddTranslateOp()
        for f, code in enumerate(codes):
            move.Set(Gf.Vec3d(0.1 * f, 0.0, 0.0), Usd.TimeCode(code))
    stage.GetRootLayer().Save()


def sphere_mesh(radius: float = 1.0, centre=(0.0, 0.0, 0.0), rings: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A closed UV sphere: ``vertices [V, 3]`` and outward-wound ``triangles [T, 3]``, ``rings`` bands from
    pole to pole (the poles on z)."""
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, 2 * rings, endpoint=False)
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.repeat(np.cos(theta)[:, None], len(phi), 1)], -1).reshape(-1, 3)
    vertices = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * radius + np.asarray(centre, np.float64)
    m, last = len(phi), len(ring) + 1
    j = np.arange(m)
    tris = [np.stack([np.zeros(m, int), 1 + j, 1 + (j + 1) % m], 1)]
    for i in range(rings - 2):
        a, b = 1 + i * m + j, 1 + i * m + (j + 1) % m
        tris += [np.stack([a, a + m, b + m], 1), np.stack([a, b + m, b], 1)]
    base = 1 + (rings - 2) * m
    tris.append(np.stack([np.full(m, last), base + (j + 1) % m, base + j], 1))
    return vertices, np.concatenate(tris).astype(np.int64)


def write_obj(path: Path, vertices: np.ndarray, triangles: np.ndarray, quads: bool = False) -> None:
    """An OBJ of the mesh (1-based faces with ``v/vt/vn``-style slashes on every other face, as tools write)."""
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in vertices]
    for k, (a, b, c) in enumerate(triangles + 1):
        lines.append(f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}" if k % 2 else f"f {a} {b} {c}")
    path.write_text("# head\n" + "\n".join(lines) + "\n")
