"""Known motions of a small asset's cards, to fit back: a rigid turn of the whole groom and a bend."""

from __future__ import annotations

import numpy as np

from cghair_format.animation import Animation, carried_normals
from cghair_format.animation.tracks import axis_rotation
from cghair_format.asset import Cards, HairAsset


def bent(cards: Cards, turn: float, bend: float) -> Cards:
    """``cards`` turned by ``turn`` radians about y through the origin, each spine then bent about x through
    its root by ``bend`` radians at the tip (growing with the square of the way along it)."""
    spine = cards.spine.astype(np.float64)
    m = cards.segments
    out = np.empty_like(spine)
    for k in range(m + 1):
        rot = axis_rotation(np.array([1.0, 0.0, 0.0]), bend * (k / m) ** 2)
        out[:, k] = (spine[:, k] - spine[:, 0]) @ rot.T + spine[:, 0]
    turn_rot = axis_rotation(np.array([0.0, 1.0, 0.0]), turn)
    out = out @ turn_rot.T
    normal = carried_normals(cards, out, turn_rot)
    return Cards(out.astype(np.float32), normal.astype(np.float32), cards.half_width, cards.group)


def known_animation(asset: HairAsset, frames: int = 4) -> Animation:
    """``frames`` frames of the asset's cards turning and bending more each frame (frame 0: the rest pose)."""
    steps = np.linspace(0, 1, frames)
    return Animation.of_frames([bent(asset.cards, 0.6 * s, 0.8 * s) for s in steps], fps=24.0)


def write_usd_cache(path, frames: list[np.ndarray], counts: np.ndarray, fps: float, first_code: float = 1.0,
                    codes: list[float] | None = None, meters_per_unit: float = 1.0) -> None:
    """A USD stage with one linear BasisCurves prim whose points are sampled at each frame: strand ``i``
    of frame ``[S, P, 3]`` has its first ``counts[i]`` points."""
    from pxr import Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(fps)
    codes = codes or [first_code + f for f in range(len(frames))]
    stage.SetStartTimeCode(codes[0])
    stage.SetEndTimeCode(codes[-1])
    curves = UsdGeom.BasisCurves.Define(stage, "/groom/strands")
    curves.CreateTypeAttr("linear")
    curves.CreateCurveVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
    keep = np.arange(frames[0].shape[1])[None, :] < np.asarray(counts)[:, None]
    for code, frame in zip(codes, frames, strict=True):
        curves.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(frame[keep], np.float32)),
                                   Usd.TimeCode(code))
    stage.GetRootLayer().Save()
