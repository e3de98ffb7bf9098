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

An animated asset (:func:`write_asset_groom` with an ``animation``) is a groom cache, as Unreal's
Groom Cache import reads one: every property of the curves and the cards sits on one uniform time
sampling of ``1 / fps`` seconds from the animation's start; per frame, the curves' ``P`` (every
strand: a strands groom cache) and the cards' ``P`` and ``N`` with each object's bounds, every
other property constant (stored once), the topology the same at every frame.

Reading (bpy 5.0, in its own interpreter: see :mod:`.blender`) imports the Alembic file in
Blender and exports a y-up USD stage that :mod:`.usd_curves` reads. A ``.blend`` is written by
Blender from our USD stage (:mod:`.usd_export`); it is in metres (Blender's unit), so it takes
no scale.
"""

from __future__ import annotations

import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import CghError
from ..strands import Strands
from ._common import StrandFileError, check_scale, finish, srgb_to_linear
from ._ogawa import Compound, Object, TimeSampling, Values, write_archive
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


def read_through_usd(path: Path, op: str, usd: Path, read: Callable):
    """``read(usd)`` after Blender's ``op`` has converted ``path`` to the USD stage ``usd``; a failure of
    either is a :class:`StrandFileError` naming ``path``, not Blender's temporary stage."""
    try:
        run_worker(op, path.resolve(), usd)
    except BlenderRunError as exc:
        raise StrandFileError(path, str(exc)) from exc
    try:
        return read(usd)
    except StrandFileError as exc:
        raise StrandFileError(path, exc.message) from exc


def load(path: str | Path) -> Strands:
    """Strands of every curves object in an Alembic file (through Blender), y-up, 1 m per unit."""
    from .usd_curves import load as load_usd

    path = Path(path)
    with tempfile.TemporaryDirectory(prefix="cgh_abc_") as tmp:
        strands = read_through_usd(path, "abc_to_usd", Path(tmp) / "groom.usdc", load_usd)
    return finish(path, strands)


def save(strands: Strands, path: str | Path) -> None:
    """Write strands as an Alembic groom (curves only, in Alembic's frame)."""
    write_groom(path, strands)


XFORM = "AbcGeom_Xform_v3"
CURVES = "AbcGeom_Curve_v2"
POLYMESH = "AbcGeom_PolyMesh_v1"
LINEAR_NONPERIODIC = np.array([1, 0, 0, 0], np.uint8)  # curveBasisAndType: linear, non-periodic, no basis


def _geom_param(name: str, values, scope: str, interpretation: str = "") -> Values:
    """An Alembic GeomParam (not indexed): an array property whose metadata names its scope
    (``con``, ``uni``: per curve, ``vtx``: per vertex) and type; ``values`` an array or a function
    of the frame giving one."""
    v = np.asarray(values(0) if callable(values) else values)
    pod = {"f": "float32_t", "i": f"int{8 * v.dtype.itemsize}_t"}[v.dtype.kind]
    md = {"geoScope": scope, "isGeomParam": "true", "podName": pod, "arrayExtent": "1",
          "podExtent": str(1 if v.ndim == 1 else v.shape[1])}
    if interpretation:
        md["interpretation"] = interpretation
    return Values(name, values if callable(values) else v, md)


def to_alembic_frame(v: np.ndarray, up_axis: str, k: float = 1.0) -> np.ndarray:
    """Vectors ``[N, 3]`` in Alembic's frame (y up), multiplied by ``k``."""
    v = np.asarray(v, np.float32) * np.float32(k)
    if up_axis == "Z":  # z-up to y-up, as Blender and Maya convert: (x, y, z) -> (x, z, -y)
        v = np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1)
    return np.ascontiguousarray(v, np.float32)


def _box(pts: np.ndarray) -> np.ndarray:
    return np.concatenate([pts.min(0), pts.max(0)]).astype(np.float64) if len(pts) else np.zeros(6)


def _positions(pts, to_frame: Callable[[np.ndarray], np.ndarray]) -> list[Values]:
    """``.selfBnds`` and ``P`` of ``pts`` (an array, or a function of the frame giving one), in
    Alembic's frame by ``to_frame``."""
    if callable(pts):
        def frame(f: int) -> np.ndarray:
            return to_frame(pts(f))

        def box(f: int) -> np.ndarray:
            return _box(frame(f))
    else:
        frame = to_frame(pts)
        box = _box(frame)
    return [Values(".selfBnds", box, {"interpretation": "box"}, scalar=True),
            Values("P", frame, {"geoScope": "vtx", "interpretation": "point"})]


def _sampled(props: list) -> list:
    """``props`` (and those of their compounds) all on the archive's time sampling."""
    for p in props:
        if isinstance(p, Compound):
            _sampled(p.properties)
        else:
            p.sampled = True
    return props


def _schema_object(name: str, schema: str, props: list) -> Object:
    return Object(name, {"schema": schema, "schemaObjTitle": f"{schema}:.geom"},
                  [Compound(".geom", props, {"schema": schema, "schemaBaseType": "AbcGeom_GeomBase_v1"})])


def groom_curves(strands: Strands, *, scale: float = 1.0, group: np.ndarray | None = None,
                 strand_ids: np.ndarray | None = None,
                 points_at: Callable[[int], np.ndarray] | None = None) -> Object:
    """``strands`` as an Alembic ICurves object named ``Strands`` with Unreal's groom attributes;
    ``points_at(f)`` (``strands.points`` at frame ``f``) makes it a groom cache."""
    k = strands.meters_per_unit * check_scale(scale)
    widths = None if strands.widths is None else np.asarray(strands.widths, np.float32) * np.float32(k)
    n = strands.count
    geom = _positions(strands.points if points_at is None else points_at,
                      lambda p: to_alembic_frame(p, strands.up_axis, k))
    geom += [Values("nVertices", strands.point_counts.astype(np.int32)),
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
    return _schema_object("Strands", CURVES, geom if points_at is None else _sampled(geom))


def card_polymesh(asset, path: Path, scale: float = 1.0, animation=None) -> Object:
    """The card strips as an Alembic IPolyMesh named ``Cards``: triangles (clockwise about the
    stored normals: Alembic's front-face winding), per-vertex normals and ``uv`` into the card
    texture atlas, written as ``<stem>_cards.png`` beside ``path`` (as the USD export does); with
    an ``animation``, ``P`` and ``N`` at each of its frames."""
    from ..geometry import card_mesh
    from .animated import card_frame
    from .usd_materials import card_atlas, write_png

    m = card_mesh(asset.cards)
    k = asset.meters_per_unit * check_scale(scale)
    atlas, st = card_atlas(asset)
    write_png(path.with_name(f"{path.stem}_cards.png"), atlas)
    if animation is None:
        vertices, normals = m.vertices, to_alembic_frame(m.normals, asset.up_axis)
    else:
        def vertices(f: int) -> np.ndarray:
            return card_frame(asset, animation, f).vertices

        def normals(f: int) -> np.ndarray:
            return to_alembic_frame(card_frame(asset, animation, f).normals, asset.up_axis)
    geom = _positions(vertices, lambda p: to_alembic_frame(p, asset.up_axis, k))
    geom += [Values(".faceIndices", np.ascontiguousarray(m.triangles, np.int32).reshape(-1)),
             Values(".faceCounts", np.full(len(m.triangles), 3, np.int32)),
             _geom_param("N", normals, "vtx", "normal"),
             _geom_param("uv", np.ascontiguousarray(st, np.float32), "vtx", "vector")]
    return _schema_object("Cards", POLYMESH, geom if animation is None else _sampled(geom))


def _xform(shape: Object) -> Object:
    """An identity IXform named like ``shape``, holding it as ``<name>Shape`` (Maya's convention;
    importers name the object after the transform)."""
    xform = Object(shape.name, {"schema": XFORM, "schemaObjTitle": f"{XFORM}:.xform"},
                   [Compound(".xform", [Values(".inherits", np.array([True]), scalar=True)], {"schema": XFORM})],
                   [shape])
    shape.name += "Shape"
    return xform


def write_groom(path: str | Path, strands: Strands, *, scale: float = 1.0, group: np.ndarray | None = None,
                strand_ids: np.ndarray | None = None) -> None:
    """Write plain ``strands`` as an Alembic groom: ``/Strands/StrandsShape`` (ICurves under an IXform)."""
    strands.validate()
    _write_shapes(Path(path), [groom_curves(strands, scale=scale, group=group, strand_ids=strand_ids)])


def write_asset_groom(path: str | Path, asset, *, scale: float = 1.0, cards: bool = False,
                      animation=None) -> None:
    """Write a :class:`~cghair_format.asset.HairAsset`'s strands (``/Strands/StrandsShape``) and, with
    ``cards``, its card strips (``/Cards/CardsShape``, IPolyMesh); with an ``animation`` (of the asset)
    every frame of it, as a groom cache."""
    from .animated import check_animation, curve_points
    from .cgh_strands import strands_from_asset

    path = Path(path)
    points_at = sampling = None
    if animation is not None:
        check_animation(asset, animation)
        sampling = TimeSampling(float(animation.fps), float(animation.start), animation.frames)

        def points_at(f: int) -> np.ndarray:
            return curve_points(asset, animation, f)
    strands = strands_from_asset(asset)
    strands.validate()
    shapes = [groom_curves(strands, scale=scale, points_at=points_at,
                           group=asset.cards.group.astype(np.int32)[asset.strand_card], strand_ids=asset.strand_ids)]
    try:
        if cards:
            shapes.append(card_polymesh(asset, path, scale, animation))
    except OSError as exc:
        raise CghError(f"{path}: cannot write the card texture beside it ({exc.strerror or exc})") from exc
    _write_shapes(path, shapes, sampling)


def _write_shapes(path: Path, shapes: list[Object], sampling: TimeSampling | None = None) -> None:
    """The archive of ``shapes``, each under an IXform, stamped with our name, the date and, when
    animated, the frame rate (``_ai_DCC_FPS``, Alembic's key for it)."""
    metadata = {"_ai_Application": f"cghair {__version__}", "_ai_DateWritten": time.strftime("%a %b %d %H:%M:%S %Y")}
    if sampling is not None:
        metadata["_ai_DCC_FPS"] = repr(sampling.fps)
    try:
        write_archive(path, [_xform(shape) for shape in shapes], metadata, sampling)
    except OSError as exc:
        raise CghError(f"{path}: cannot write the Alembic file ({exc.strerror or exc})") from exc


def export_groom(path: Path, *, asset=None, strands: Strands | None = None, cards: bool = False,
                 scale: float = 1.0, animation=None) -> None:
    """Write ``asset`` (curves, and ``cards``) or ``strands`` as Alembic (``.abc``, our own writer)
    or as a Blender scene (``.blend`` through Blender: curves with the Principled Hair BSDF, cards
    with their texture); an ``animation`` of the asset goes to ``.abc`` as a groom cache."""
    from .usd_export import export_usd

    ext = path.suffix.lower()
    if ext not in (".abc", ".blend"):
        raise CghError(f"{path}: groom export writes .abc or .blend here, not {ext or 'no extension'}")
    if check_scale(scale) != 1.0 and ext == ".blend":
        raise CghError(f"{path}: a .blend is in metres (Blender's unit); --scale applies to .abc, USD and the rest")
    if animation is not None and ext != ".abc":
        raise CghError(f"{path}: an animation exports to .abc or USD; a .blend takes the rest pose only")
    if ext == ".abc":
        if asset is None:
            write_groom(path, strands, scale=scale)
        else:
            write_asset_groom(path, asset, scale=scale, cards=cards, animation=animation)
        return
    with tempfile.TemporaryDirectory(prefix="cgh_blend_") as tmp:
        usd = Path(tmp) / "groom.usdc"
        if asset is not None:
            export_usd(usd, asset=asset, cards=cards)
        else:
            export_usd(usd, strands=strands)
        run_worker("usd_to_blend", usd, path.resolve())
