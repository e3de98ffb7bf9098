"""One USD stage for a hair asset or plain strands: curves, card meshes and Gaussian splats.

Layout (``/Hair`` is the default prim, an Xform with Unreal's ``GroomAPI`` applied when
``groom=True``):

- ``/Hair/Strands``: linear BasisCurves with ``widths``, ``primvars:displayColor`` (the
  view-independent colour: SH band 0, converted to linear Rec.709) and
  ``primvars:displayOpacity`` per vertex, plus the groom primvars Unreal's groom importer reads:
  per vertex ``groom_color`` (linear), ``groom_width``; per curve ``groom_group_id``,
  ``groom_guide`` (0: rendered strand), and ``groom_id`` / ``groom_root_uv`` where the asset has
  strand ids / root UVs; constant ``groom_version_major/minor`` (1, 5). The names follow Unreal's
  groom attribute schema (documented for Alembic grooms). Bound to ``StrandMaterial``.
- ``/Hair/Cards``: the card strips as a triangle Mesh, wound counter-clockwise about their stored
  normals, with ``primvars:st`` into the card texture atlas (``<name>_cards.png`` beside the
  file) bound through ``CardMaterial`` as colour and opacity.
- ``/Hair/Gaussians``: ``UsdVol.ParticleField3DGaussianSplat`` (usd-core >= 26): positions,
  orientations, scales (standard deviations), opacities in [0, 1] and SH coefficients
  (particle-major, 3DGS real-SH convention) with their degree.
- ``/Hair/GaussianPoints``: the same Gaussians as ``UsdGeom.Points`` (positions, widths: twice
  the smallest standard deviation, linear displayColor, displayOpacity), for importers that drop
  the splat field (Blender 5.0 does).
- ``/Hair/Materials``: the preview-surface materials (:mod:`.usd_materials`).

Given an ``animation``, what moves gets time samples, one per frame (:mod:`.usd_animation`).

Colours are linear Rec.709: the colour attributes say so (``colorSpace = lin_rec709_scene``) and
``/Hair`` carries ``ColorSpaceAPI`` with the same name where usd-core has it. The stage's
``metersPerUnit`` and ``upAxis`` come from the asset or strands; ``scale`` multiplies every
coordinate and width and divides ``metersPerUnit``, so the hair keeps its real size.
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
from ._common import check_scale, scale_strands, srgb_to_linear, warn

EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
ROOT = "/Hair"
GROOM_VERSION = (1, 5)  # Unreal's groom attribute schema version (groom_version_major/minor)
LINEAR = "lin_rec709_scene"  # Gf.ColorSpaceNames.LinearRec709
DROPPED = ("Blender 5.0's USD importer drops {g} (ParticleField3DGaussianSplat) and shows {p} "
           "(points: positions, widths, colours; no orientation or SH); splat-aware importers show both")


def export_usd(path: str | Path, *, asset: HairAsset | None = None, strands: Strands | None = None,
               curves: bool = True, cards: bool = False, gaussians: bool = False, groom: bool = True,
               scale: float = 1.0, animation=None) -> None:
    """Write ``asset`` (or plain ``strands``) to a USD file; ``cards``/``gaussians`` need an asset.
    ``scale`` multiplies coordinates and widths (output units per input unit); an ``animation``
    (:class:`~cghair_format.animation.Animation` of the asset) adds its frames as time samples."""
    path = Path(path)
    scale = check_scale(scale)
    if (asset is None) == (strands is None):
        raise CghError("export_usd needs exactly one of asset= or strands=")
    if animation is not None:
        from .animated import check_animation

        check_animation(asset, animation)
    if asset is None and (cards or gaussians):
        raise CghError("card meshes and Gaussians exist only for a .cgh asset, not for plain strands")
    if not (curves or cards or gaussians):
        raise CghError("nothing to export: enable curves, cards or gaussians")
    src = asset if asset is not None else strands

    def build(stage, root, out: Path) -> None:
        if groom:
            root.AddAppliedSchema("GroomAPI")
        if asset is not None:
            if generator := getattr(asset, "generator", None):
                root.SetCustomDataByKey("cghair:generator", str(generator))
            if attribution := getattr(asset, "attribution", None):
                root.SetCustomDataByKey("cghair:attribution", str(attribution))
        if curves:
            if asset is not None:
                from .cgh_strands import point_average, strands_from_asset

                s = strands_from_asset(asset)
                opacity = point_average(asset.opacity.astype(np.float32)[..., None], asset.counts)[..., 0]
                opacity = opacity[asset.real_points()]
                group = asset.cards.group.astype(np.int32)[asset.strand_card]
                root_uv, ids = asset.root_uv, asset.strand_ids
            else:
                s, opacity, group, root_uv, ids = strands, None, None, strands.root_uv, None
            curves_prim = write_curves(stage, f"{ROOT}/Strands", scale_strands(s, scale), opacity=opacity,
                                       group=group, root_uv=root_uv, strand_ids=ids, groom=groom).GetPrim()
            from .usd_materials import bind_curve_material

            bind_curve_material(stage, curves_prim, opacity is not None)
        if cards:
            write_cards(stage, f"{ROOT}/Cards", asset, out, scale)
        if gaussians:
            from ..gaussians import decode_gaussians

            write_gaussian_prims(stage, decode_gaussians(asset), scale)
        if animation is not None:
            from .usd_animation import write_time_samples

            write_time_samples(stage, ROOT, asset, animation, scale, curves=curves, cards=cards, gaussians=gaussians)

    write_stage(path, build, src.meters_per_unit / scale, src.up_axis)


def export_gaussians_usd(path: str | Path, gaussians, meters_per_unit: float = 1.0, up_axis: str = "Y",
                         scale: float = 1.0) -> None:
    """Write bare Gaussians (e.g. read from a 3DGS PLY) as ``/Hair/Gaussians`` and ``/Hair/GaussianPoints``."""
    scale = check_scale(scale)
    write_stage(Path(path), lambda stage, root, out: write_gaussian_prims(stage, gaussians, scale),
                meters_per_unit / scale, up_axis)


def write_gaussian_prims(stage, g, scale: float = 1.0) -> None:
    """The Gaussians as a splat field and as points, warning (one line) what Blender drops."""
    if scale != 1.0:
        from ..gaussians import Gaussians

        g = Gaussians(g.means * np.float32(scale), g.rotations, g.scales * np.float32(scale), g.opacities, g.sh)
    write_gaussians(stage, f"{ROOT}/Gaussians", g)
    write_gaussian_points(stage, f"{ROOT}/GaussianPoints", g)
    warn(DROPPED.format(g=f"{ROOT}/Gaussians", p=f"{ROOT}/GaussianPoints"))


def write_stage(path: Path, build: Callable, meters_per_unit: float, up_axis: str) -> None:
    """Create a stage at ``path`` (a .usdz is packaged from a temporary .usdc) with units, up axis
    and the ``/Hair`` default prim, let ``build(stage, root_prim, path)`` fill it, and save it."""
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
        if hasattr(Usd, "ColorSpaceAPI"):  # usd-core >= 25.11
            Usd.ColorSpaceAPI.Apply(root).CreateColorSpaceNameAttr(LINEAR)
        build(stage, root, path)  # the final path: files written beside it are named after it
        stage.GetRootLayer().Save()


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
        rgb = Vt.Vec3fArray.FromNumpy(srgb_to_linear(strands.colors))
        for name in ("displayColor", "groom_color") if groom else ("displayColor",):
            pv = api.CreatePrimvar(name, Sdf.ValueTypeNames.Color3fArray, vertex)
            pv.Set(rgb)
            pv.GetAttr().SetColorSpace(LINEAR)
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


def card_faces(triangles: np.ndarray) -> np.ndarray:
    """:func:`~cghair_format.geometry.card_mesh`'s triangles wound counter-clockwise about the
    stored normals, as renderers expect: its ``(L_k, R_k, L_k+1)`` order faces along
    ``b x t = -n`` (the bitangent is ``n x t``), so two corners swap."""
    return np.ascontiguousarray(triangles[:, [0, 2, 1]])


def write_cards(stage, prim_path: str, asset: HairAsset, usd_path: Path, scale: float = 1.0):
    """The card strips as one triangle Mesh with per-vertex normals, ``st`` into the card texture
    atlas (written as ``<stem>_cards.png`` beside ``usd_path``) and the card material bound."""
    from pxr import Sdf, UsdGeom, Vt

    from ..geometry import card_mesh
    from .usd_materials import bind_card_material, card_atlas, write_png

    m = card_mesh(asset.cards)
    vertices = np.ascontiguousarray(m.vertices * np.float32(scale), np.float32)
    mesh = UsdGeom.Mesh.Define(stage, prim_path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(vertices))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(m.triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(card_faces(m.triangles).astype(np.int32).reshape(-1)))
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(m.normals, np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([vertices.min(0), vertices.max(0)])))
    atlas, st_atlas = card_atlas(asset)
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                           UsdGeom.Tokens.vertex)
    st.Set(Vt.Vec2fArray.FromNumpy(st_atlas))
    png = usd_path.with_name(f"{usd_path.stem}_cards.png")
    write_png(png, atlas)
    bind_card_material(stage, mesh.GetPrim(), png, usd_path)
    return mesh


def write_gaussians(stage, prim_path: str, g):
    """``g`` (:class:`~cghair_format.gaussians.Gaussians`) as a ParticleField3DGaussianSplat."""
    from pxr import Sdf, UsdGeom, UsdVol, Vt

    if not hasattr(UsdVol, "ParticleField3DGaussianSplat"):
        raise CghError("Gaussian export needs usd-core >= 26 (UsdVol.ParticleField3DGaussianSplat); "
                       "upgrade with: pip install -U usd-core")
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
    pv = UsdGeom.PrimvarsAPI(prim).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                                 UsdGeom.Tokens.vertex)
    pv.Set(Vt.Vec3fArray.FromNumpy(_linear_band0(g)))
    pv.GetAttr().SetColorSpace(LINEAR)
    return splat


def _linear_band0(g) -> np.ndarray:
    """The view-independent colour of each Gaussian (SH band 0), linear."""
    from ..gaussians import SH_C0

    return srgb_to_linear(np.clip(SH_C0 * np.asarray(g.sh, np.float32)[:, 0] + 0.5, 0, 1))


def write_gaussian_points(stage, prim_path: str, g):
    """``g`` as ``UsdGeom.Points``: positions, widths (twice the smallest standard deviation),
    linear displayColor and displayOpacity: the form Blender 5.0 imports (as a point cloud)."""
    from pxr import Sdf, UsdGeom, Vt

    points = UsdGeom.Points.Define(stage, prim_path)
    means = np.ascontiguousarray(g.means, np.float32)
    points.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(means))
    points.CreateWidthsAttr(Vt.FloatArray.FromNumpy((2 * np.asarray(g.scales, np.float32).min(1)).astype(np.float32)))
    points.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    points.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([means.min(0), means.max(0)])))
    api = UsdGeom.PrimvarsAPI(points.GetPrim())
    pv = api.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
    pv.Set(Vt.Vec3fArray.FromNumpy(_linear_band0(g)))
    pv.GetAttr().SetColorSpace(LINEAR)
    api.CreatePrimvar("displayOpacity", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex).Set(
        Vt.FloatArray.FromNumpy(np.ascontiguousarray(g.opacities, np.float32)))
    return points
