"""USD BasisCurves with time-sampled points (``.usd``, ``.usda``, ``.usdc``, ``.usdz``), frame by frame.

The frames are the time codes at which any BasisCurves prim's points, or the transform of the prim or of
one of its ancestors, are sampled (one frame at the earliest time when nothing is), evenly spaced; the
frame rate is the stage's ``timeCodesPerSecond`` over their spacing. Each frame is read as
:mod:`.usd_curves` reads a static stage (world space, cubic curves evaluated); every frame must keep the
first frame's curves and point counts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._common import StrandFileError
from .strand_cache import StrandCache
from .usd_curves import _curves, _pxr, open_stage

SPACING_TOLERANCE = 1e-6  # relative: time codes further off an even spacing are refused


def _time_codes(path: str | Path, stage, prims: list) -> np.ndarray:
    """The sampled time codes of the curves' points and transforms, sorted; evenly spaced or refused."""
    _, UsdGeom = _pxr()
    codes: set[float] = set()
    for prim in prims:
        codes.update(UsdGeom.BasisCurves(prim).GetPointsAttr().GetTimeSamples())
        p = prim
        while p and not p.IsPseudoRoot():
            if p.IsA(UsdGeom.Xformable):
                codes.update(UsdGeom.Xformable(p).GetTimeSamples())
            p = p.GetParent()
    return even_time_codes(path, codes, "the curves")


def even_time_codes(path: str | Path, codes: set[float], what: str) -> np.ndarray:
    """``codes`` sorted, or a :class:`StrandFileError` saying ``what`` is sampled unevenly."""
    times = np.array(sorted(codes), np.float64)
    if len(times) > 2:
        step = np.diff(times)
        if np.abs(step - step[0]).max() > SPACING_TOLERANCE * max(abs(step[0]), 1.0):
            raise StrandFileError(path, f"{what} are sampled at uneven time codes ({times[0]:g}, {times[1]:g}, "
                                        f"..., {times[-1]:g}); resample the animation to a constant frame rate")
    return times


def load_cache(path: str | Path) -> StrandCache:
    """The animated strands of every BasisCurves prim of the stage, in traversal order."""
    Usd, UsdGeom = _pxr()
    stage = open_stage(path)
    prims = [p for p in stage.Traverse() if p.IsA(UsdGeom.BasisCurves)]
    if not prims:
        raise StrandFileError(path, "the USD stage has no BasisCurves prim")
    codes = _time_codes(path, stage, prims)
    per_second = float(stage.GetTimeCodesPerSecond())
    if not (np.isfinite(per_second) and per_second > 0):
        raise StrandFileError(path, f"timeCodesPerSecond must be positive, got {per_second}")
    fps = per_second / float(codes[1] - codes[0]) if len(codes) > 1 else per_second
    start = float(codes[0]) / per_second if len(codes) else 0.0
    times = [Usd.TimeCode(float(c)) for c in codes] or [Usd.TimeCode.EarliestTime()]

    paths = [p.GetPath() for p in prims]

    def frame(i: int) -> tuple[np.ndarray, np.ndarray]:  # holds the stage: its prims live as long as it
        parts = [_curves(path, UsdGeom.BasisCurves(stage.GetPrimAtPath(p)), times[i]) for p in paths]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    _, counts = frame(0)
    kw = {}
    if UsdGeom.StageHasAuthoredMetersPerUnit(stage):
        kw["meters_per_unit"] = float(UsdGeom.GetStageMetersPerUnit(stage))
    if stage.HasAuthoredMetadata("upAxis"):
        kw["up_axis"] = str(UsdGeom.GetStageUpAxis(stage))
    return StrandCache(str(path), counts.astype(np.int64), len(times), fps, start, frame, **kw)
