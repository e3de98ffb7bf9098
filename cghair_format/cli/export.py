"""``cgh export FILE -o OUT``: a .cgh asset (or strands, or a 3DGS PLY) to USD or to a 3DGS PLY.

USD (``.usd .usda .usdc .usdz``): strands as curves (default), ``--cards`` card meshes,
``--gaussians`` the Gaussians as a ParticleField3DGaussianSplat; ``--all`` for everything.
PLY (``.ply``): the decoded Gaussians as a standard 3DGS PLY.
"""

from __future__ import annotations

import argparse
from pathlib import Path

USD_EXTS = (".usd", ".usda", ".usdc", ".usdz")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="a .cgh asset, a strand file, or a 3DGS .ply")
    p.add_argument("-o", "--output", required=True, help="out.usda | .usdc | .usdz | .usd, or out.ply (3DGS)")
    p.add_argument("--no-curves", dest="curves", action="store_false", help="leave the strand curves out")
    p.add_argument("--cards", action="store_true", help="add the hair cards as a Mesh with UVs (.cgh only)")
    p.add_argument("--gaussians", action="store_true", help="add the Gaussians as a 3DGS particle field (.cgh only)")
    p.add_argument("--all", action="store_true", help="curves, cards and Gaussians")
    p.add_argument("--no-groom", dest="groom", action="store_false",
                   help="omit Unreal's GroomAPI schema and groom_* primvars")
    p.add_argument("--units", type=float, metavar="M", help="metres per unit of strand input (overrides the file)")
    p.add_argument("--up", choices=("Y", "Z", "y", "z"), help="up axis of strand input (overrides the file)")


def _is_3dgs_ply(path: str) -> bool:
    with open(path, "rb") as f:
        head = f.read(4096)
    return head.startswith(b"ply") and b"f_dc_0" in head


def run(args: argparse.Namespace) -> int:
    from ..errors import CghError

    src, out = Path(args.file), Path(args.output)
    ext = out.suffix.lower()
    if ext not in USD_EXTS + (".ply",):
        raise CghError(f"{out}: export writes {', '.join(USD_EXTS)} or .ply (3DGS), not {ext or 'no extension'}")
    if args.all:
        args.curves = args.cards = args.gaussians = True
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
    from ..exchange.usd_export import export_usd

    strands = load_strands(src, units=args.units, up=args.up)
    export_usd(out, strands=strands, groom=args.groom)
    print(f"{out}: {strands.count:,} strands as linear BasisCurves")
    return 0


def _export_asset(src: Path, out: Path, args: argparse.Namespace) -> int:
    if out.suffix.lower() == ".ply":
        from ..codec import read_with_gaussians
        from ..exchange.ply_3dgs import write_3dgs_ply

        g = read_with_gaussians(src)[1]
        write_3dgs_ply(g, out)
        print(f"{out}: {g.count:,} Gaussians as a 3DGS PLY (SH degree {g.sh_degree}, written as degree 3)")
        return 0
    from ..codec import read
    from ..exchange.usd_export import export_usd

    asset = read(src)
    export_usd(out, asset=asset, curves=args.curves, cards=args.cards, gaussians=args.gaussians, groom=args.groom)
    parts = [name for name, on in (("curves", args.curves), ("cards", args.cards), ("gaussians", args.gaussians))
             if on]
    print(f"{out}: {asset.n_strands:,} strands, {asset.cards.count:,} cards, {asset.n_gaussians:,} Gaussians; "
          f"wrote {', '.join(parts)}")
    return 0


def _export_splats(src: Path, out: Path, args: argparse.Namespace) -> int:
    from ..errors import CghError
    from ..exchange.ply_3dgs import read_3dgs_ply, write_3dgs_ply

    g = read_3dgs_ply(src)
    if out.suffix.lower() == ".ply":
        write_3dgs_ply(g, out)
    else:
        if args.cards:
            raise CghError(f"{src}: a 3DGS PLY has no hair cards")
        from ..exchange.usd_export import export_gaussians_usd

        export_gaussians_usd(out, g)
    print(f"{out}: {g.count:,} Gaussians from the 3DGS PLY {src}")
    return 0
