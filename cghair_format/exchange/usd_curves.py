"""USD BasisCurves (``.usd``, ``.usda``, ``.usdc``, ``.usdz``) as strands, through usd-core.

Reading gathers every BasisCurves prim of the stage in world space (its local-to-world transform
applied), at the earliest authored time. Linear curves keep their vertices; cubic curves
(bezier, bspline, catmullRom; nonperiodic, pinned or periodic wrap) are evaluated at
``CUBIC_SAMPLES`` points per segment. ``widths`` and ``primvars:displayColor`` (else
``primvars:groom_color``) are mapped to points from any interpolation (constant, uniform,
varying, vertex, faceVarying); they are kept only when every curves prim has them.
``metersPerUnit`` and ``upAxis`` are taken where authored.
Writing produces one linear BasisCurves prim (see :mod:`.usd_export`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import require
from ..strands import Strands
from ._common import (
    StrandFileError,
    colours,
    finish,
    float32,
    linear_to_srgb,
    nonnegative,
    offsets_from_counts,
    read_bytes,
)

CUBIC_SAMPLES = 4
BASIS = {
    "bezier": np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 3, 0, 0], [1, 0, 0, 0]], np.float64),
    "bspline": np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 0, 3, 0], [1, 4, 1, 0]], np.float64) / 6,
    "catmullRom": np.array([[-1, 3, -3, 1], [2, -5, 4, -1], [-1, 0, 1, 0], [0, 2, 0, 0]], np.float64) / 2,
}
VSTEP = {"bezier": 3, "bspline": 1, "catmullRom": 1}


def _pxr():
    require("pxr.Usd", "usd", "USD strand import/export", package="usd-core")
    from pxr import Usd, UsdGeom

    return Usd, UsdGeom


def open_stage(path: str | Path):
    """The USD stage of ``path``, or a :class:`StrandFileError` with USD's own message."""
    Usd, _ = _pxr()
    with open(path, "rb") as f:
        text = f.read(6) == b"#usda "
    if text:  # usd-core reads text layers as UTF-8, and its errors about other bytes fail to print
        try:
            read_bytes(path).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise StrandFileError(path, f"a .usda file must be UTF-8 text; byte offset {exc.start} is not") from None
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as exc:  # pxr raises Tf.ErrorException (a RuntimeError) with USD's own message
        raise StrandFileError(path, f"USD cannot open the file: {_usd_message(exc)}") from exc
    if stage is None:
        raise StrandFileError(path, "USD cannot open the file")
    return stage


def load(path: str | Path) -> Strands:
    Usd, UsdGeom = _pxr()
    stage = open_stage(path)
    time = Usd.TimeCode.EarliestTime()
    parts = []
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.BasisCurves):
            parts.append(_curves(path, UsdGeom.BasisCurves(prim), time))
    if not parts:
        raise StrandFileError(path, "the USD stage has no BasisCurves prim")
    points = np.concatenate([p[0] for p in parts])
    counts = np.concatenate([p[1] for p in parts])
    colors = widths = None
    if all(p[2] is not None for p in parts):
        colors = np.concatenate([p[2] for p in parts])
    if all(p[3] is not None for p in parts):
        widths = np.concatenate([p[3] for p in parts])
    kw = {}
    if UsdGeom.StageHasAuthoredMetersPerUnit(stage):
        kw["meters_per_unit"] = float(UsdGeom.GetStageMetersPerUnit(stage))
    if stage.HasAuthoredMetadata("upAxis"):
        kw["up_axis"] = str(UsdGeom.GetStageUpAxis(stage))
    strands = Strands(float32(path, "points (in world space)", points), offsets_from_counts(counts), colors,
                      widths, **kw)
    return finish(path, strands, {"meters_per_unit": "metersPerUnit", "colors": "displayColor / groom_color",
                                  "widths": "widths"})


def _usd_message(exc: Exception) -> str:
    """The readable part of a Tf error: the quoted texts after each ``Error in '...' at line ... :``."""
    try:
        text = str(exc)
    except UnicodeDecodeError:  # USD quotes the file's bytes in its messages
        return "its error message is not UTF-8 text"
    msgs = [part.split(" : ", 1)[1].strip().strip("'") for part in text.split("\n\tError in ") if " : " in part]
    return "; ".join(m.strip() for m in msgs)[:400] or text.strip()[:400]


def _curves(path, curves, time):
    prim_path = curves.GetPath()
    pts = curves.GetPointsAttr().Get(time)
    cnt = curves.GetCurveVertexCountsAttr().Get(time)
    if pts is None or cnt is None:
        raise StrandFileError(path, f"{prim_path}: BasisCurves without points or curveVertexCounts")
    pts = np.asarray(pts, np.float64).reshape(-1, 3)
    cnt = np.asarray(cnt, np.int64)
    if (cnt < 1).any() or cnt.sum() != len(pts):
        raise StrandFileError(path, f"{prim_path}: curveVertexCounts add up to {int(cnt.sum())}, "
                                    f"the prim has {len(pts)} points")
    xf = np.asarray(curves.ComputeLocalToWorldTransform(time), np.float64)
    if not np.allclose(xf, np.eye(4)):
        pts = pts @ xf[:3, :3] + xf[3, :3]  # USD matrices act on row vectors
    ctype = curves.GetTypeAttr().Get(time) or "cubic"
    basis = curves.GetBasisAttr().Get(time) or "bezier"
    wrap = curves.GetWrapAttr().Get(time) or "nonperiodic"
    if ctype == "linear":
        plan = None
    else:
        if basis not in BASIS:
            raise StrandFileError(path, f"{prim_path}: unsupported cubic basis {basis!r}")
        plan = _cubic_plan(path, prim_path, cnt, basis, wrap)
    color_pv = None
    from pxr import UsdGeom

    api = UsdGeom.PrimvarsAPI(curves.GetPrim())
    for name in ("displayColor", "groom_color"):
        pv = api.GetPrimvar(name)
        if pv and pv.HasAuthoredValue():
            color_pv = pv
            break
    colors = None
    if color_pv is not None:
        raw = np.asarray(color_pv.ComputeFlattened(time), np.float64)
        raw = raw.reshape(len(raw), -1)[:, :3]  # color3f, or color4f (Blender writes groom_color as RGBA)
        raw = colours(path, f"{prim_path} primvars:{color_pv.GetPrimvarName()}", raw)
        colors = np.clip(_per_point(path, prim_path, raw, color_pv.GetInterpolation(), cnt, plan, ctype), 0, 1)
        if not color_pv.GetAttr().GetColorSpace().startswith("srgb"):
            colors = linear_to_srgb(colors)
    widths = None
    wattr = curves.GetWidthsAttr()
    w = wattr.Get(time)
    if w is not None and len(w):
        w = nonnegative(path, f"{prim_path} widths", w).reshape(-1, 1)
        # a cubic through widths that fall to 0 can dip below it: clamp (finish refuses negative widths)
        widths = np.maximum(_per_point(path, prim_path, w, curves.GetWidthsInterpolation(), cnt, plan, ctype)[:, 0],
                            0).astype(np.float32)
    if plan is None:
        return pts, cnt, colors, widths
    return _eval_cubic(pts, plan), plan["counts"], colors, widths


def _cubic_plan(path, prim_path, cnt: np.ndarray, basis: str, wrap: str) -> dict:
    """Where each output point of cubic curves comes from: its segment's 4 control points
    (indices into the points extended by one phantom point before and after each curve) and t."""
    vstep, n_all = VSTEP[basis], int(cnt.sum())
    n_curves = len(cnt)
    starts = np.concatenate([[0], np.cumsum(cnt)[:-1]]).astype(np.int64)
    segs, sample_seg, sample_t, nsegs = [], [], [], []
    ts = np.arange(CUBIC_SAMPLES) / CUBIC_SAMPLES
    total = 0
    for i, (s0, n) in enumerate(zip(starts.tolist(), cnt.tolist(), strict=True)):
        if wrap == "periodic":
            idx = np.arange(n + (3 if basis != "bezier" else 1)) % n + s0
        elif wrap == "pinned" and basis != "bezier":
            idx = np.concatenate([[n_all + i], np.arange(n) + s0, [n_all + n_curves + i]])
        else:
            idx = np.arange(n) + s0
        if len(idx) < 4 or (len(idx) - 4) % vstep:
            raise StrandFileError(path, f"{prim_path}: a {basis} curve cannot have {n} vertices "
                                        f"with wrap {wrap!r}")
        nseg = (len(idx) - 4) // vstep + 1
        segs.append(idx[(np.arange(nseg) * vstep)[:, None] + np.arange(4)[None, :]])
        # samples: t in [0, 1) on each segment, then t = 1 at the curve's end
        sample_seg.append(np.concatenate([np.repeat(np.arange(nseg), CUBIC_SAMPLES), [nseg - 1]]) + total)
        sample_t.append(np.concatenate([np.tile(ts, nseg), [1.0]]))
        nsegs.append(nseg)
        total += nseg
    nsegs = np.array(nsegs, np.int64)
    return {"segs": np.concatenate(segs), "seg": np.concatenate(sample_seg), "t": np.concatenate(sample_t),
            "counts": nsegs * CUBIC_SAMPLES + 1, "nseg": nsegs, "starts": starts, "n": cnt, "m": BASIS[basis]}


def _eval_cubic(values: np.ndarray, plan: dict) -> np.ndarray:
    """Evaluate per-control-point ``values [N, D]`` at the plan's sample points."""
    s0, n = plan["starts"], plan["n"]
    first = 2 * values[s0] - values[s0 + np.minimum(1, n - 1)]  # pinned phantom points
    last_i = s0 + n - 1
    last = 2 * values[last_i] - values[last_i - np.minimum(1, n - 1)]
    ext = np.concatenate([values, first, last])
    t = plan["t"]
    w = np.stack([t ** 3, t ** 2, t, np.ones_like(t)], 1) @ plan["m"]  # [samples, 4]
    return np.einsum("sk,skd->sd", w, ext[plan["segs"][plan["seg"]]])


def _per_point(path, prim_path, values: np.ndarray, interp: str, cnt: np.ndarray, plan, ctype: str):
    """Expand a primvar of any interpolation to one value per output point."""
    n_pts = int(cnt.sum())
    if interp == "constant" or len(values) == 1:
        per_cv = np.repeat(values[:1], n_pts, 0)
    elif interp == "uniform":
        if len(values) != len(cnt):
            raise StrandFileError(path, f"{prim_path}: uniform primvar needs {len(cnt)} values, has {len(values)}")
        per_cv = np.repeat(values, cnt, 0)
    elif interp == "vertex" or ctype == "linear":  # linear varying/faceVarying == vertex
        if len(values) != n_pts:
            raise StrandFileError(path, f"{prim_path}: {interp} primvar needs {n_pts} values, has {len(values)}")
        per_cv = values
    else:  # varying / faceVarying on cubic curves: one value per segment end
        nseg = plan["nseg"]
        if len(values) != int((nseg + 1).sum()):
            raise StrandFileError(path, f"{prim_path}: {interp} primvar needs {int((nseg + 1).sum())} "
                                        f"values, has {len(values)}")
        out, pos = [], 0
        for segs_n in nseg.tolist():
            v = values[pos:pos + segs_n + 1]
            pos += segs_n + 1
            x = np.arange(segs_n * CUBIC_SAMPLES + 1) / CUBIC_SAMPLES
            out.append(np.stack([np.interp(x, np.arange(segs_n + 1), v[:, j]) for j in range(v.shape[1])], 1))
        return np.concatenate(out)
    if plan is None:
        return per_cv
    return _eval_cubic(per_cv, plan)


def save(strands: Strands, path: str | Path) -> None:
    from .usd_export import export_usd

    export_usd(path, strands=strands)
