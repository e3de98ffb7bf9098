"""Time samples on the prims of :mod:`.usd_export` for an animated asset.

The static prims keep their rest-pose values as defaults (what a reader that asks for no time gets);
frame ``f`` adds time samples at time code ``start * fps + f`` (:func:`.animated.time_code`) for what
moves: ``/Hair/Strands`` points, ``/Hair/Cards`` points and normals, ``/Hair/Gaussians`` positions,
orientations and scales, ``/Hair/GaussianPoints`` points and widths, and each prim's extent. Topology,
widths of the curves, colours, opacities, SH and UVs stay the rest pose's. The stage says
``timeCodesPerSecond = framesPerSecond = fps`` and the first and last frames' time codes.
"""

from __future__ import annotations

import numpy as np

from ..animation import Animation
from ..asset import HairAsset
from .animated import card_frame, curve_points, gaussian_frame, time_code


def write_time_samples(stage, root: str, asset: HairAsset, animation: Animation, scale: float, *, curves: bool,
                       cards: bool, gaussians: bool) -> None:
    """Add every frame of ``animation`` to the prims exported under ``root`` (``scale`` as the static
    export's)."""
    from pxr import UsdGeom, Vt

    fps, k = float(animation.fps), np.float32(scale)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(time_code(animation, 0))
    stage.SetEndTimeCode(time_code(animation, animation.frames - 1))
    strands = UsdGeom.BasisCurves(stage.GetPrimAtPath(f"{root}/Strands")) if curves else None
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"{root}/Cards")) if cards else None
    splat = stage.GetPrimAtPath(f"{root}/Gaussians") if gaussians else None
    points = UsdGeom.Points(stage.GetPrimAtPath(f"{root}/GaussianPoints")) if gaussians else None
    vec3 = Vt.Vec3fArray.FromNumpy
    for f in range(animation.frames):
        t = time_code(animation, f)
        if strands is not None:
            _set_points(strands, curve_points(asset, animation, f) * k, t)
        if mesh is not None:
            m = card_frame(asset, animation, f)
            _set_points(mesh, m.vertices * k, t)
            mesh.GetNormalsAttr().Set(vec3(np.ascontiguousarray(m.normals, np.float32)), t)
        if splat is not None:
            means, rotations, scales, _ = gaussian_frame(asset, animation, f)
            means, scales = np.ascontiguousarray(means * k, np.float32), np.ascontiguousarray(scales * k, np.float32)
            splat.GetAttribute("positions").Set(vec3(means), t)
            xyzw = np.ascontiguousarray(np.asarray(rotations, np.float32)[:, [1, 2, 3, 0]])  # Gf storage order
            splat.GetAttribute("orientations").Set(Vt.QuatfArray.FromNumpy(xyzw), t)
            splat.GetAttribute("scales").Set(vec3(scales), t)
            splat.GetAttribute("extent").Set(_extent(means), t)
            _set_points(points, means, t)
            points.GetWidthsAttr().Set(Vt.FloatArray.FromNumpy((2 * scales.min(1)).astype(np.float32)), t)


def _extent(pts: np.ndarray):
    from pxr import Vt

    return Vt.Vec3fArray.FromNumpy(np.stack([pts.min(0), pts.max(0)]).astype(np.float32))


def _set_points(prim, pts: np.ndarray, t: float) -> None:
    """A point-based prim's points and extent at time code ``t``."""
    from pxr import Vt

    pts = np.ascontiguousarray(pts, np.float32)
    prim.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts), t)
    prim.GetExtentAttr().Set(_extent(pts), t)
