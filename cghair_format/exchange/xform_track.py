"""An animated transform (a head's track): the world matrix of one xformable prim at every frame, read
from USD (``.usd .usda .usdc .usdz``) or Alembic (``.abc``, through Blender).

The frames are the time codes at which the prim's transform, or that of one of its ancestors, is
sampled, evenly spaced (as :mod:`.usd_cache` takes a strand cache's); the frame rate is the stage's
``timeCodesPerSecond`` over their spacing. The prim is the one named, or else the only xformable prim
whose own transform has more than one time sample. An Alembic file is imported by Blender, which writes
it as a time-sampled, y-up USD stage under ``/root`` (Alembic's ``/Head`` becomes ``/root/Head``; a
prim named as in the Alembic file is looked up there); Alembic states no units: it is read as metres, as
Blender takes it.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._common import StrandFileError, readable_file
from .usd_cache import even_time_codes
from .usd_curves import _pxr, open_stage

USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
BLENDER_ROOT = "/root"  # where Blender's USD export puts the objects it imported from Alembic


@dataclass(frozen=True)
class XformSamples:
    """The world transform of ``prim`` at ``frames`` evenly spaced times, ``fps`` a second from ``start``
    seconds: ``x -> matrix[f, :3, :3] x + matrix[f, :3, 3]`` in the file's units and axes."""

    path: str
    prim: str
    matrix: np.ndarray  # [F, 4, 4] float64, column vectors
    fps: float
    start: float
    meters_per_unit: float | None = None  # as the file states it, or None
    up_axis: str | None = None

    @property
    def frames(self) -> int:
        return int(self.matrix.shape[0])


def animated_prims(stage) -> list[str]:
    """The paths of the stage's xformable prims whose own transform has more than one time sample."""
    _, UsdGeom = _pxr()
    return [str(p.GetPath()) for p in stage.Traverse()
            if p.IsA(UsdGeom.Xformable) and len(UsdGeom.Xformable(p).GetTimeSamples()) > 1]


def _head_prim(path: str | Path, stage, prim: str | None):
    """The prim the track follows: ``prim``, or the single animated xformable prim (refusing none or several)."""
    _, UsdGeom = _pxr()
    if prim is None:
        found = animated_prims(stage)
        if not found:
            raise StrandFileError(path, "no xformable prim has a time-sampled transform: give a file with the "
                                        "head's animation")
        if len(found) > 1:
            names = ", ".join(found[:6]) + (", ..." if len(found) > 6 else "")
            raise StrandFileError(path, f"{len(found)} animated xformable prims ({names}): name the head's with "
                                        "--head-prim")
        prim = found[0]
    try:
        p = stage.GetPrimAtPath(prim)
    except Exception:  # pxr refuses a malformed path with its own exception type
        p = None
    if not p or not p.IsA(UsdGeom.Xformable):
        raise StrandFileError(path, f"{prim!r} is not an xformable prim of the stage; animated ones: "
                                    f"{', '.join(animated_prims(stage)) or 'none'}")
    return p


def _time_codes(path: str | Path, prim) -> np.ndarray:
    """The time codes at which ``prim``'s or an ancestor's transform is sampled: at least two, evenly spaced."""
    _, UsdGeom = _pxr()
    codes: set[float] = set()
    p = prim
    while p and not p.IsPseudoRoot():
        if p.IsA(UsdGeom.Xformable):
            codes.update(UsdGeom.Xformable(p).GetTimeSamples())
        p = p.GetParent()
    if len(codes) < 2:
        raise StrandFileError(path, f"the transform of {prim.GetPath()} is not animated (fewer than two time "
                                    "samples on it and its parents)")
    return even_time_codes(path, codes, f"the transforms of {prim.GetPath()}")


def load_usd_xforms(path: str | Path, prim: str | None = None) -> XformSamples:
    """The world transforms of ``prim`` (or the single animated xformable prim) of a USD stage."""
    Usd, UsdGeom = _pxr()
    stage = open_stage(path)
    head = _head_prim(path, stage, prim)
    codes = _time_codes(path, head)
    per_second = float(stage.GetTimeCodesPerSecond())
    if not (np.isfinite(per_second) and per_second > 0):
        raise StrandFileError(path, f"timeCodesPerSecond must be positive, got {per_second}")
    cache = UsdGeom.XformCache()
    matrix = np.empty((len(codes), 4, 4))
    for f, code in enumerate(codes):
        cache.SetTime(Usd.TimeCode(float(code)))
        matrix[f] = np.array(cache.GetLocalToWorldTransform(head), np.float64).T  # USD's rows -> columns
    if not np.isfinite(matrix).all():
        bad = int(np.flatnonzero(~np.isfinite(matrix).all(axis=(1, 2)))[0])
        raise StrandFileError(path, f"the transform of {head.GetPath()} at frame {bad} holds NaN or infinite values")
    kw = {}
    if UsdGeom.StageHasAuthoredMetersPerUnit(stage):
        kw["meters_per_unit"] = float(UsdGeom.GetStageMetersPerUnit(stage))
    if stage.HasAuthoredMetadata("upAxis"):
        kw["up_axis"] = str(UsdGeom.GetStageUpAxis(stage))
    return XformSamples(str(path), str(head.GetPath()), matrix, per_second / float(codes[1] - codes[0]),
                        float(codes[0]) / per_second, **kw)


def load_alembic_xforms(path: Path, prim: str | None = None) -> XformSamples:
    """The same for an Alembic file, through Blender (see the module's docstring for the prim's name)."""
    from .alembic import BlenderRunError, run_worker

    with tempfile.TemporaryDirectory(prefix="cgh_abc_xforms_") as tmp:
        usd = Path(tmp) / "xforms.usdc"
        try:
            run_worker("abc_xforms_to_usd", path.resolve(), usd)
            samples = load_usd_xforms(usd, None if prim is None else BLENDER_ROOT + "/" + prim.lstrip("/"))
        except (BlenderRunError, StrandFileError) as exc:  # name the Alembic file, not Blender's stage
            raise StrandFileError(path, getattr(exc, "message", str(exc))) from exc
    head = samples.prim[len(BLENDER_ROOT):] if samples.prim.startswith(BLENDER_ROOT + "/") else samples.prim
    return XformSamples(str(path), head, samples.matrix, samples.fps, samples.start, 1.0, samples.up_axis)


def load_xforms(path: str | Path, prim: str | None = None) -> XformSamples:
    """The animated transform of ``prim`` (or of the single animated xformable prim) in a USD or Alembic file."""
    p, ext = readable_file(path, (*USD_EXTENSIONS, ".abc"), "a transform track")
    return load_alembic_xforms(p, prim) if ext == ".abc" else load_usd_xforms(p, prim)
