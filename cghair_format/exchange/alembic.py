"""Alembic (``.abc``) grooms written by our own Ogawa writer; Alembic reading and Blender
(``.blend``) scenes through Blender.

Writing goes through :mod:`._ogawa` (no Alembic library installs from PyPI): an ``IXform``
``/Strands`` holding an ``ICurves`` ``/Strands/StrandsShape`` (linear, non-periodic) with ``P``,
``nVertices``, per-vertex ``width`` (the diameter) and, in ``.arbGeomParams``, the attributes of
Unreal's groom Alembic schema: ``groom_color`` (per vertex, linear Rec.709 C3f),
``groom_width`` (per vertex), ``groom_group_id`` and ``groom_guide`` (per curve; 0: rendered
strand), ``groom_id`` and ``groom_root_uv`` (per curve, where the asset has them) and the
constant ``groom_version_major/minor`` (int16); with cards, an ``IPolyMesh`` ``/Cards/CardsShape``
(triangles, normals, ``uv`` into the card atlas written beside the file). One static sample,
y up; Alembic states no units, so coordinates and widths are metres times the export scale
(Unreal and Houdini grooms are in centimetres: ``--scale 100``).

Reading (bpy 5.0, in its own interpreter: see :mod:`.blender`) imports the Alembic file in
Blender and exports a y-up USD stage that :mod:`.usd_curves` reads. A ``.blend`` is written by
Blender from our USD stage (:mod:`.usd_export`); it is in metres (Blender's unit), so it takes
no scale.
"""

from __future__ import annotations

import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import CghError
from ..strands import Strands
from ._common import StrandFileError, check_scale, finish, srgb_to_linear
from ._ogawa import Compound, Object, Values, write_archive
from .usd_export import GROOM_VERSION

WORKER = Path(__file__).with_name("_bpy_worker") / "groom.py"
TIMEOUT_S = 600


class BlenderRunError(CghError, RuntimeError):
    """Blender failed on a conversion; the message carries the end of its output."""


def run_worker(op: str, src: Path, dst: Path) -> None:
    """Run the Blender worker's ``op`` from ``src`` to ``dst`` (see ``_bpy_worker/groom.py``)."""
    from .blender import find_blender_python

    python = find_blender_python()
    try:
        proc = subprocess.run([python, str(WORKER), op, str(src), str(dst)],
                              capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired as exc:
        raise BlenderRunError(f"Blender did not finish {op} within {TIMEOUT_S} s") from exc
    if proc.returncode != 0 or "CGH_DONE" not in proc.stdout or not dst.exists():
        tail = [ln for ln in (proc.stdout + proc.stderr).strip().splitlines() if ln.strip()][-3:]
        raise BlenderRunError(f"Blender failed ({op}, exit {proc.returncode}): {' | '.join(tail)}")


def load(path: str | Path) -> Strands:
    """Strands of every curves object in an Alembic file (through Blender), y-up, 1 m per unit."""
    from .usd_curves import load as load_usd

    path = Path(path)
    with tempfile.TemporaryDirectory(prefix="cgh_abc_") as tmp:
        usd = Path(tmp) / "groom.usdc"
        try:
            run_worker("abc_to_usd", path.resolve(), usd)
        except BlenderRunError as exc:
            raise StrandFileError(path, str(exc)) from exc
        try:
            strands = load_usd(usd)
        except StrandFileError as exc:  # name the Alembic file, not Blender's temporary stage
            raise StrandFileError(path, exc.message) from exc
    return finish(path, strands)


def save(strands: Strands, path: str | Path) -> None:
    """Write strands as an Alembic groom (curves only, in Alembic's frame)."""
    write_groom(path, strands)


XFORM = "AbcGeom_Xform_v3"
CURVES = "AbcGeom_Curve_v2"
POLYMESH = "AbcGeom_PolyMesh_v1"
LINEAR_NONPERIODIC = np.array([1, 0, 0, 0], np.uint8)  # curveBasisAndType: linear, non-periodic, no basis


def _geom_param(name: str, values: np.ndarray, scope: str, interpretation: str = "") -> Values:
    """An Alembic GeomParam (not indexed): an array property whose metadata names its scope
    (``con``, ``uni``: per curve, ``vtx``: per vertex) and type."""
    v = np.asarray(values)
    pod = {"f": "float32_t", "i": f"int{8 * v.dtype.itemsize}_t"}[v.dtype.kind]
    md = {"geoScope": scope, "isGeomParam": "true", "podName": pod, "arrayExtent": "1",
          "podExtent": str(1 if v.ndim == 1 else v.shape[1])}
    if interpretation:
        md["interpretation"] = interpretation
    return Values(name, v, md)


def to_alembic_frame(v: np.ndarray, up_axis: str, k: float = 1.0) -> np.ndarray:
    """Vectors ``[N, 3]`` in Alembic's frame (y up), multiplied by ``k``."""
    v = np.asarray(v, np.float32) * np.float32(k)
    if up_axis == "Z":  # z-up to y-up, as Blender and Maya convert: (x, y, z) -> (x, z, -y)
        v = np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1)
    return np.ascontiguousarray(v, np.float32)


def _bounds(pts: np.ndarray) -> Values:
    box = np.concatenate([pts.min(0), pts.max(0)]).astype(np.float64) if len(pts) else np.zeros(6)
    return Values(".selfBnds", box, {"interpretation": "box"}, scalar=True)


def _schema_object(name: str, schema: str, props: list) -> Object:
    return Object(name, {"schema": schema, "schemaObjTitle": f"{schema}:.geom"},
                  [Compound(".geom", props, {"schema": schema, "schemaBaseType": "AbcGeom_GeomBase_v1"})])


def groom_curves(strands: Strands, *, scale: float = 1.0, group: np.ndarray | None = None,
                 strand_ids: np.ndarray | None = None) -> Object:
    """``strands`` as an Alembic ICurves object named ``Strands`` with Unreal's groom attributes."""
    k = strands.meters_per_unit * check_scale(scale)
    pts = to_alembic_frame(strands.points, strands.up_axis, k)
    widths = None if strands.widths is None else np.asarray(strands.widths, np.float32) * np.float32(k)
    n = strands.count
    geom = [_bounds(pts), Values("P", pts, {"geoScope": "vtx", "interpretation": "point"}),
            Values("nVertices", strands.point_counts.astype(np.int32)),
            Values("curveBasisAndType", LINEAR_NONPERIODIC, scalar=True)]
    arb = []
    if widths is not None:
        geom.append(_geom_param("width", widths, "vtx"))
        arb.append(_geom_param("groom_width", widths, "vtx"))
    if strands.colors is not None:
        arb.append(_geom_param("groom_color", srgb_to_linear(strands.colors), "vtx", "rgb"))
    gid = np.zeros(n, np.int32) if group is None else np.asarray(group, np.int32)
    arb += [_geom_param("groom_group_id", gid, "uni"),
            _geom_param("groom_guide", np.zeros(n, np.int16), "uni")]  # all rendered strands
    if strand_ids is not None:
        arb.append(_geom_param("groom_id", np.asarray(strand_ids).astype(np.int32), "uni"))
    if strands.root_uv is not None:
        arb.append(_geom_param("groom_root_uv", np.asarray(strands.root_uv, np.float32), "uni", "vector"))
    arb += [_geom_param("groom_version_major", np.array([GROOM_VERSION[0]], np.int16), "con"),
            _geom_param("groom_version_minor", np.array([GROOM_VERSION[1]], np.int16), "con")]
    geom.append(Compound(".arbGeomParams", arb))
    return _schema_object("Strands", CURVES, geom)


def card_polymesh(asset, path: Path, scale: float = 1.0) -> Object:
    """The card strips as an Alembic IPolyMesh named ``Cards``: triangles (clockwise about the
    stored normals: Alembic's front-face winding), per-vertex normals and ``uv`` into the card
    texture atlas, written as ``<stem>_cards.png`` beside ``path`` (as the USD export does)."""
    from ..geometry import card_mesh
    from .usd_materials import card_atlas, write_png

    m = card_mesh(asset.cards)
    pts = to_alembic_frame(m.vertices, asset.up_axis, asset.meters_per_unit * check_scale(scale))
    atlas, st = card_atlas(asset)
    write_png(path.with_name(f"{path.stem}_cards.png"), atlas)
    geom = [_bounds(pts), Values("P", pts, {"geoScope": "vtx", "interpretation": "point"}),
            Values(".faceIndices", np.ascontiguousarray(m.triangles, np.int32).reshape(-1)),
            Values(".faceCounts", np.full(len(m.triangles), 3, np.int32)),
            _geom_param("N", to_alembic_frame(m.normals, asset.up_axis), "vtx", "normal"),
            _geom_param("uv", np.ascontiguousarray(st, np.float32), "vtx", "vector")]
    return _schema_object("Cards", POLYMESH, geom)


def _xform(shape: Object) -> Object:
    """An identity IXform named like ``shape``, holding it as ``<name>Shape`` (Maya's convention;
    importers name the object after the transform)."""
    xform = Object(shape.name, {"schema": XFORM, "schemaObjTitle": f"{XFORM}:.xform"},
                   [Compound(".xform", [Values(".inherits", np.array([True]), scalar=True)], {"schema": XFORM})],
                   [shape])
    shape.name += "Shape"
    return xform


def write_groom(path: str | Path, strands: Strands, *, scale: float = 1.0, group: np.ndarray | None = None,
                strand_ids: np.ndarray | None = None, cards_of=None) -> None:
    """Write ``strands`` as an Alembic groom: ``/Strands/StrandsShape`` (ICurves under an IXform)
    and, given ``cards_of`` (a :class:`~cghair_format.asset.HairAsset`), ``/Cards/CardsShape``
    (IPolyMesh)."""
    path = Path(path)
    strands.validate()
    shapes = [groom_curves(strands, scale=scale, group=group, strand_ids=strand_ids)]
    try:
        if cards_of is not None:
            shapes.append(card_polymesh(cards_of, path, scale))
        write_archive(path, [_xform(shape) for shape in shapes],
                      {"_ai_Application": f"cghair {__version__}",
                       "_ai_DateWritten": time.strftime("%a %b %d %H:%M:%S %Y")})
    except OSError as exc:
        raise CghError(f"{path}: cannot write the Alembic file ({exc.strerror or exc})") from exc


def export_groom(path: Path, *, asset=None, strands: Strands | None = None, cards: bool = False,
                 scale: float = 1.0) -> None:
    """Write ``asset`` (curves, and ``cards``) or ``strands`` as Alembic (``.abc``, our own writer)
    or as a Blender scene (``.blend`` through Blender: curves with the Principled Hair BSDF, cards
    with their texture)."""
    from .usd_export import export_usd

    ext = path.suffix.lower()
    if ext not in (".abc", ".blend"):
        raise CghError(f"{path}: groom export writes .abc or .blend here, not {ext or 'no extension'}")
    if check_scale(scale) != 1.0 and ext == ".blend":
        raise CghError(f"{path}: a .blend is in metres (Blender's unit); --scale applies to .abc, USD and the rest")
    if ext == ".abc":
        if asset is None:
            write_groom(path, strands, scale=scale)
        else:
            from .cgh_strands import strands_from_asset

            write_groom(path, strands_from_asset(asset), scale=scale, cards_of=asset if cards else None,
                        group=asset.cards.group.astype(np.int32)[asset.strand_card], strand_ids=asset.strand_ids)
        return
    with tempfile.TemporaryDirectory(prefix="cgh_blend_") as tmp:
        usd = Path(tmp) / "groom.usdc"
        if asset is not None:
            export_usd(usd, asset=asset, cards=cards)
        else:
            export_usd(usd, strands=strands)
        run_worker("usd_to_blend", usd, path.resolve())
