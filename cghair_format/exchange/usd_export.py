"""One USD stage for a hair asset or plain strands: curves, card meshes and Gaussian splats.

Layout (``/Hair`` is the default prim, an Xform with Unreal's ``GroomAPI`` applied when
``groom=True``):

- ``/Hair/Strands``: linear BasisCurves with ``widths``, ``primvars:displayColor`` (the
  view-independent colour: SH band 0) and ``primvars:displayOpacity`` per vertex, plus the groom
  primvars Unreal's groom importer reads: per vertex ``groom_color``, ``groom_width``; per curve
  ``groom_group_id``, ``groom_guide`` (0: rendered strand), and ``groom_id`` / ``groom_root_uv``
  where the asset has strand ids / root UVs; constant ``groom_version_major/minor`` (1, 5). The
  names follow Unreal's groom attribute schema (documented for Alembic grooms).
- ``/Hair/Cards``: the card strips as a triangle Mesh with normals and ``primvars:st`` UVs.
- ``/Hair/Gaussians``: ``UsdVol.ParticleField3DGaussianSplat`` (usd-core >= 26): positions,
  orientations, scales (standard deviations), opacities in [0, 1] and SH coefficients
  (particle-major, 3DGS real-SH convention) with their degree.

The stage's ``metersPerUnit`` and ``upAxis`` come from the asset or strands.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..asset import HairAsset
from ..atomic import atomic_path
from ..errors import CghError, require
from ..strands import Strands

EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
ROOT = "/Hair"
GROOM_VERSION = (1, 5)  # Unreal's groom attribute schema version (groom_version_major/minor)


def export_usd(path: str | Path, *, asset: HairAsset | None = None, strands: Strands | None = None,
               curves: bool = True, cards: bool = False, gaussians: bool = False, groom: bool = True) -> None:
    """Write ``asset`` (or plain ``strands``) to a USD file; ``cards``/``gaussians`` need an asset."""
    path = Path(path)
    if (asset is None) == (strands is None):
        raise CghError("export_usd needs exactly one of asset= or strands=")
    if asset is None and (cards or gaussians):
        raise CghError("card meshes and Gaussians exist only for a .cgh asset, not for plain strands")
    if not (curves or cards or gaussians):
        raise CghError("nothing to export: enable curves, cards or gaussians")
    src = asset if asset is not None else strands

    def build(stage, root) -> None:
        if groom:
            root.AddAppliedSchema("GroomAPI")
        if asset is not None:
            if generator := getattr(asset, "generator", None):
                root.SetCustomDataByKey("cghair:generator", str(generator))
            if attribution := getattr(asset, "attribution", None):
                root.SetCustomDataByKey("cghair:attribution", str(attribution))
        if curves:
            if asset is not None:
                from .cgh_strands import strands_from_asset

                s = strands_from_asset(asset)
                opacity = _point_average(asset.opacity.astype(np.float32)[..., None])[..., 0].reshape(-1)
                group = asset.cards.group.astype(np.int32)[asset.strand_card]
                root_uv, ids = asset.root_uv, asset.strand_ids
            else:
                s, opacity, group, root_uv, ids = strands, None, None, None, None
            write_curves(stage, f"{ROOT}/Strands", s, opacity=opacity, group=group, root_uv=root_uv,
                         strand_ids=ids, groom=groom)
        if cards:
            write_cards(stage, f"{ROOT}/Cards", asset)
        if gaussians:
            from ..gaussians import decode_gaussians

            write_gaussians(stage, f"{ROOT}/Gaussians", decode_gaussians(asset))

    write_stage(path, build, src.meters_per_unit, src.up_axis)


def export_gaussians_usd(path: str | Path, gaussians, meters_per_unit: float = 1.0, up_axis: str = "Y") -> None:
    """Write bare Gaussians (e.g. read from a 3DGS PLY) as ``/Hair/Gaussians``."""
    write_stage(Path(path), lambda stage, root: write_gaussians(stage, f"{ROOT}/Gaussians", gaussians),
                meters_per_unit, up_axis)


def write_stage(path: Path, build: Callable, meters_per_unit: float, up_axis: str) -> None:
    """Create a stage at ``path`` (a .usdz is packaged from a temporary .usdc) with units, up axis
    and the ``/Hair`` default prim, let ``build(stage, root_prim)`` fill it, and save it."""
    ext = path.suffix.lower()
    if ext not in EXTENSIONS:
        raise CghError(f"{path}: USD export writes {', '.join(EXTENSIONS)}, not {ext or 'no extension'}")
    require("pxr.Usd", "usd", "USD export", package="usd-core")
    from pxr import Usd, UsdGeom, UsdUtils

    if ext == ".usdz":
        with tempfile.TemporaryDirectory() as tmp:
            inner = Path(tmp) / (path.stem + ".usdc")
            write_stage(inner, build, meters_per_unit, up_axis)
            with atomic_path(path) as out:
                if not UsdUtils.CreateNewUsdzPackage(str(inner), str(out)):
                    raise CghError(f"{path}: usd-core could not write the .usdz package")
        return
    with atomic_path(path) as out:
        stage = Usd.Stage.CreateNew(str(out))
        UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
        root = UsdGeom.Xform.Define(stage, ROOT).GetPrim()
        stage.SetDefaultPrim(root)
        build(stage, root)
        stage.GetRootLayer().Save()


def _point_average(seg: np.ndarray) -> np.ndarray:
    """Per-segment values ``[S, P-1, D]`` to per-point ``[S, P, D]`` (mean of adjacent segments)."""
    out = np.empty((seg.shape[0], seg.shape[1] + 1, seg.shape[2]), np.float32)
    out[:, 0], out[:, -1] = seg[:, 0], seg[:, -1]
    out[:, 1:-1] = (seg[:, 1:] + seg[:, :-1]) / 2
    return out


def write_curves(stage, prim_path: str, strands: Strands, *, opacity: np.ndarray | None = None,
                 group: np.ndarray | None = None, root_uv: np.ndarray | None = None,
                 strand_ids: np.ndarray | None = None, groom: bool = True):
    """Linear BasisCurves for ``strands`` with widths, displayColor/Opacity and groom primvars."""
    from pxr import Sdf, UsdGeom, Vt

    curves = UsdGeom.BasisCurves.Define(stage, prim_path)
    pts = np.ascontiguousarray(strands.points, np.float32)
    counts = strands.point_counts.astype(np.int32)
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    curves.CreateWrapAttr(UsdGeom.Tokens.nonperiodic)
    curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(counts))
    curves.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([pts.min(0), pts.max(0)])))
    if strands.widths is not None:
        curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(np.ascontiguousarray(strands.widths, np.float32)))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    api = UsdGeom.PrimvarsAPI(curves.GetPrim())
    vertex, uniform, constant = UsdGeom.Tokens.vertex, UsdGeom.Tokens.uniform, UsdGeom.Tokens.constant
    if strands.colors is not None:
        rgb = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(strands.colors, np.float32))
        api.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, vertex).Set(rgb)
        if groom:
            api.CreatePrimvar("groom_color", Sdf.ValueTypeNames.Color3fArray, vertex).Set(rgb)
    if opacity is not None:
        api.CreatePrimvar("displayOpacity", Sdf.ValueTypeNames.FloatArray, vertex).Set(
            Vt.FloatArray.FromNumpy(np.ascontiguousarray(opacity, np.float32)))
    if groom:
        if strands.widths is not None:
            api.CreatePrimvar("groom_width", Sdf.ValueTypeNames.FloatArray, vertex).Set(
                Vt.FloatArray.FromNumpy(np.ascontiguousarray(strands.widths, np.float32)))
        gid = np.zeros(strands.count, np.int32) if group is None else np.asarray(group, np.int32)
        api.CreatePrimvar("groom_group_id", Sdf.ValueTypeNames.IntArray, uniform).Set(Vt.IntArray.FromNumpy(gid))
        api.CreatePrimvar("groom_guide", Sdf.ValueTypeNames.IntArray, uniform).Set(  # all rendered strands
            Vt.IntArray.FromNumpy(np.zeros(strands.count, np.int32)))
        for name, value in (("groom_version_major", GROOM_VERSION[0]), ("groom_version_minor", GROOM_VERSION[1])):
            api.CreatePrimvar(name, Sdf.ValueTypeNames.Int, constant).Set(value)
        if strand_ids is not None:
            api.CreatePrimvar("groom_id", Sdf.ValueTypeNames.IntArray, uniform).Set(
                Vt.IntArray.FromNumpy(np.asarray(strand_ids).astype(np.int32)))
        if root_uv is not None:
            api.CreatePrimvar("groom_root_uv", Sdf.ValueTypeNames.Float2Array, uniform).Set(
                Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(root_uv, np.float32)))
    return curves


def write_cards(stage, prim_path: str, asset: HairAsset):
    """The card strips as one triangle Mesh with per-vertex normals and ``st`` UVs."""
    from pxr import Sdf, UsdGeom, Vt

    from ..geometry import card_mesh

    m = card_mesh(asset.cards)
    mesh = UsdGeom.Mesh.Define(stage, prim_path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(m.vertices, np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(m.triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(m.triangles.astype(np.int32).reshape(-1)))
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(m.normals, np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([m.vertices.min(0), m.vertices.max(0)])))
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                           UsdGeom.Tokens.vertex)
    st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(m.uvs, np.float32)))
    return mesh


def write_gaussians(stage, prim_path: str, g):
    """``g`` (:class:`~cghair_format.gaussians.Gaussians`) as a ParticleField3DGaussianSplat."""
    from pxr import Sdf, UsdGeom, UsdVol, Vt

    if not hasattr(UsdVol, "ParticleField3DGaussianSplat"):
        raise CghError("Gaussian export needs usd-core >= 26 (UsdVol.ParticleField3DGaussianSplat); "
                       "upgrade with: pip install -U usd-core")
    from ..gaussians import SH_C0

    splat = UsdVol.ParticleField3DGaussianSplat.Define(stage, prim_path)
    prim = splat.GetPrim()
    means = np.ascontiguousarray(g.means, np.float32)
    prim.GetAttribute("positions").Set(Vt.Vec3fArray.FromNumpy(means))
    xyzw = np.ascontiguousarray(np.asarray(g.rotations, np.float32)[:, [1, 2, 3, 0]])  # Gf storage order
    prim.GetAttribute("orientations").Set(Vt.QuatfArray.FromNumpy(xyzw))
    prim.GetAttribute("scales").Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(g.scales, np.float32)))
    prim.GetAttribute("opacities").Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(g.opacities, np.float32)))
    prim.GetAttribute("radiance:sphericalHarmonicsDegree").Set(int(g.sh_degree))
    prim.GetAttribute("radiance:sphericalHarmonicsCoefficients").Set(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(g.sh, np.float32).reshape(-1, 3)))
    prim.GetAttribute("extent").Set(Vt.Vec3fArray.FromNumpy(np.stack([means.min(0), means.max(0)])))
    rgb = np.clip(SH_C0 * np.asarray(g.sh, np.float32)[:, 0] + 0.5, 0, 1).astype(np.float32)
    UsdGeom.PrimvarsAPI(prim).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                           UsdGeom.Tokens.vertex).Set(Vt.Vec3fArray.FromNumpy(rgb))
    return splat
