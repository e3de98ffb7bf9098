"""``cgh export FILE -o OUT``: a .cgh asset (or strands, or a 3DGS PLY) to USD, a 3DGS PLY, Alembic
or a Blender scene.

USD (``.usd .usda .usdc .usdz``): strands as curves (default), ``--cards`` card meshes,
``--gaussians`` the Gaussians (a ParticleField3DGaussianSplat and Points); ``--all`` for everything.
PLY (``.ply``): the decoded Gaussians as a standard 3DGS PLY, y down unless ``--up`` says otherwise.
Alembic (``.abc``, our own writer) and Blender (``.blend``, through bpy): curves (and ``--cards``).
``--scale`` multiplies every coordinate and width (output units per input unit).
An animated .cgh exports its frames to USD (time samples) and Alembic (a groom cache); ``--frames A:B``
takes some of them, ``--rest`` the rest pose alone.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import CghError
from .argtypes import positive_float

USD_EXTS = (".usd", ".usda", ".usdc", ".usdz")
GROOM_EXTS = (".abc", ".blend")
PLY_UPS = ("-y", "y", "z")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="a .cgh asset, a strand file, or a 3DGS .ply")
    p.add_argument("-o", "--output", required=True,
                   help="out.usda | .usdc | .usdz | .usd, out.ply (3DGS), out.abc (Alembic) or out.blend")
    p.add_argument("--no-curves", dest="curves", action="store_false", help="leave the strand curves out")
    p.add_argument("--cards", action="store_true", help="add the hair cards as a textured Mesh (.cgh only)")
    p.add_argument("--gaussians", action="store_true",
                   help="add the Gaussians as a 3DGS particle field and as points (.cgh only)")
    p.add_argument("--all", action="store_true", help="curves, cards and Gaussians")
    p.add_argument("--no-groom", dest="groom", action="store_false",
                   help="omit Unreal's GroomAPI schema and groom_* primvars")
    p.add_argument("--scale", type=positive_float, default=1.0, metavar="S",
                   help="multiply coordinates and widths by S; the units shrink alike (100: metres to cm)")
    p.add_argument("--up", choices=PLY_UPS, default=None,
                   help="up axis of a 3DGS .ply (default -y: the INRIA/COLMAP convention 3DGS viewers expect)")
    p.add_argument("--frames", metavar="A:B",
                   help="of an animated .cgh, export frames A (included) to B (excluded); A or B may be left out, "
                        "negatives count from the end (--frames=-10:)")
    p.add_argument("--rest", action="store_true", help="export an animated .cgh's rest pose alone")
    p.add_argument("--units", type=float, metavar="M", help="metres per unit of strand input (overrides the file)")
    p.add_argument("--input-up", choices=("Y", "Z", "y", "z"), help="up axis of strand input (overrides the file)")


def _is_3dgs_ply(path: str) -> bool:
    with open(path, "rb") as f:
        head = f.read(4096)
    return head.startswith(b"ply") and b"f_dc_0" in head


def run(args: argparse.Namespace) -> int:
    src, out = Path(args.file), Path(args.output)
    ext = out.suffix.lower()
    if ext not in USD_EXTS + GROOM_EXTS + (".ply",):
        raise CghError(f"{out}: export writes {', '.join(USD_EXTS + GROOM_EXTS)} or .ply (3DGS), "
                       f"not {ext or 'no extension'}")
    if args.up is not None and ext != ".ply":
        raise CghError(f"--up chooses a 3DGS PLY's up axis; {ext} states its own (y up)")
    if args.all:
        args.curves = args.cards = args.gaussians = True
    if args.rest and args.frames is not None:
        raise CghError("--frames exports frames of the animation, --rest the rest pose alone: give one")
    if src.suffix.lower() != ".cgh" and (args.frames is not None or args.rest):
        raise CghError(f"{src}: --frames and --rest apply to an animated .cgh asset")
    if src.suffix.lower() == ".cgh":
        return _export_asset(src, out, args)
    if src.suffix.lower() == ".ply" and _is_3dgs_ply(str(src)):
        return _export_splats(src, out, args)
    if ext == ".ply":
        raise CghError(f"{src}: a 3DGS PLY needs Gaussians: give a .cgh asset (for strands use cgh convert)")
    if args.cards or args.gaussians:
        raise CghError(f"{src}: card meshes and Gaussians exist only in a .cgh asset; plain strands export "
                       "as curves only")
    from ..exchange import load_strands

    strands = load_strands(src, units=args.units, up=args.input_up)
    if ext in GROOM_EXTS:
        from ..exchange.alembic import export_groom

        export_groom(out, strands=strands, scale=args.scale)
    else:
        from ..exchange.usd_export import export_usd

        export_usd(out, strands=strands, groom=args.groom, scale=args.scale)
    print(f"{out}: {strands.count:,} strands as curves")
    return 0


def _export_asset(src: Path, out: Path, args: argparse.Namespace) -> int:
    ext = out.suffix.lower()
    if ext == ".ply":
        if args.frames is not None:
            raise CghError(f"{out}: a 3DGS PLY holds one pose (the rest pose); export frames to USD or .abc")
        from ..codec import read_with_gaussians
        from ..exchange.ply_3dgs import DEFAULT_UP, write_3dgs_ply

        asset, g = read_with_gaussians(src)
        up = args.up or DEFAULT_UP
        write_3dgs_ply(g, out, source_up=asset.up_axis, up=up, scale=args.scale,
                       meters_per_unit=asset.meters_per_unit)
        print(f"{out}: {g.count:,} Gaussians as a 3DGS PLY (SH degree {g.sh_degree}, written as degree 3), "
              f"up {up}")
        return 0
    from ..codec import read

    asset = read(src)
    animation = None if args.rest else asset_animation(src, args.frames)
    if ext in GROOM_EXTS:
        from ..exchange.alembic import export_groom

        if args.gaussians or not args.curves:
            raise CghError(f"{out}: {ext} export writes the curves (and --cards); Gaussians go to USD or .ply")
        if animation is not None and ext == ".blend":
            raise CghError(f"{src} is animated: its frames export to .abc or USD; for a .blend add --rest")
        export_groom(out, asset=asset, cards=args.cards, scale=args.scale, animation=animation)
    else:
        from ..exchange.usd_export import export_usd

        export_usd(out, asset=asset, curves=args.curves, cards=args.cards, gaussians=args.gaussians,
                   groom=args.groom, scale=args.scale, animation=animation)
    parts = [name for name, on in (("curves", args.curves), ("cards", args.cards), ("gaussians", args.gaussians))
             if on]
    moving = "" if animation is None else f" at {animation.frames} frames ({animation.fps:g} fps)"
    print(f"{out}: {asset.n_strands:,} strands, {asset.cards.count:,} cards, {asset.n_gaussians:,} Gaussians; "
          f"wrote {', '.join(parts)}{moving}")
    return 0


def asset_animation(path: Path, frames: str | None):
    """The animation stored in the .cgh at ``path`` (``None`` where it has none), cut to ``frames``
    (``A:B``). It comes from ``cghair_format.read_animation(path)``, the animation part's reader, where
    the package has one; without it every .cgh exports as the rest pose."""
    import cghair_format

    from ..exchange.animated import frame_range

    reader = getattr(cghair_format, "read_animation", None)
    animation = None if reader is None else reader(path)
    if animation is None:
        if frames is not None:
            raise CghError(f"{path}: --frames needs an animated .cgh; this one has no animation")
        return None
    return animation if frames is None else frame_range(animation, frames)


def _export_splats(src: Path, out: Path, args: argparse.Namespace) -> int:
    from ..exchange.ply_3dgs import DEFAULT_UP, read_3dgs_ply, write_3dgs_ply

    g = read_3dgs_ply(src, up="Y")  # from the file's stated up axis (else y down) to y up
    ext = out.suffix.lower()
    if ext == ".ply":
        write_3dgs_ply(g, out, up=args.up or DEFAULT_UP, scale=args.scale)
    elif ext in GROOM_EXTS:
        raise CghError(f"{src}: a 3DGS PLY has no curves for {ext}; export it to USD or .ply")
    else:
        if args.cards:
            raise CghError(f"{src}: a 3DGS PLY has no hair cards")
        from ..exchange.usd_export import export_gaussians_usd

        export_gaussians_usd(out, g, scale=args.scale)
    print(f"{out}: {g.count:,} Gaussians from the 3DGS PLY {src}")
    return 0
