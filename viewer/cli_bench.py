"""``cgh bench-viewer``: the viewer's load time, and for each rasterizer and a few splat budgets
the per-stage frame times and the PSNR against full quality and the reference splatter."""

from __future__ import annotations

import argparse

from .cli import add_raster_arguments, add_turn_argument


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", nargs="?", default=None, help="a .cgh file (or use --synthetic)")
    parser.add_argument("--synthetic", type=int, default=None, metavar="N_STRANDS",
                        help="benchmark a procedural asset of N strands built in memory instead of a file")
    parser.add_argument("--points", type=int, default=101,
                        help="points per synthetic strand (default 101: 100 Gaussians per strand)")
    parser.add_argument("--width", type=int, default=1920, help="frame width (default 1920)")
    parser.add_argument("--height", type=int, default=1080, help="frame height (default 1080)")
    parser.add_argument("--frames", type=int, default=3, help="frames to time (default 3)")
    parser.add_argument("--sort", choices=("auto", "gpu", "cpu"), default="auto",
                        help="sort used in the frame time (both are timed and reported)")
    add_raster_arguments(parser, rasterizers=("both", "compute", "raster", "auto"), default="both", many_budgets=True,
                         budget_help="splat budgets to time besides full quality (default: 1/4, 1/8 and 1/16 of "
                                     "the Gaussians)")
    parser.add_argument("--reference-size", type=int, nargs=2, default=(480, 270), metavar=("W", "H"),
                        help="size of the reference splatter's render for the PSNR (default 480 270)")
    parser.add_argument("--no-reference", action="store_true", help="skip the reference splatter (needs torch)")
    parser.add_argument("--animate", action="store_true",
                        help="also time an animated frame (card upload + GPU decode + splat) against the static "
                             "one, on the file's animation or a simulated nod; with the reference, the PSNR of "
                             "frames of it against the native splatter on the CPU's Gaussians, SH turned")
    parser.add_argument("--simulate", action="store_true",
                        help="like --animate, with the cards simulated live each frame (simulation time included)")
    add_turn_argument(parser)
    parser.add_argument("--json", default=None, metavar="PATH", help="also write the figures as JSON")


def run(args: argparse.Namespace) -> int:
    import json

    from cghair_format.errors import CghError

    from .bench import benchmark, format_report

    if (args.file is None) == (args.synthetic is None):
        raise CghError("give either a .cgh FILE or --synthetic N_STRANDS")
    if args.synthetic is not None and args.synthetic < 1:
        raise CghError(f"--synthetic must be >= 1 strand, got {args.synthetic}")
    if args.points < 2:
        raise CghError(f"--points must be >= 2, got {args.points}")
    if args.frames < 1:
        raise CghError(f"--frames must be >= 1, got {args.frames}")
    for name in ("width", "height"):
        if not 1 <= getattr(args, name) <= 16384:
            raise CghError(f"--{name} must be between 1 and 16384, got {getattr(args, name)}")
    for name, value in zip(("W", "H"), args.reference_size, strict=True):
        if not 1 <= value <= 16384:
            raise CghError(f"--reference-size {name} must be between 1 and 16384, got {value}")
    rasterizers = {"both": ("compute", "raster"), "auto": ("compute",)}.get(args.rasterizer, (args.rasterizer,))
    result = benchmark(path=args.file, synthetic=args.synthetic, points=args.points, width=args.width,
                       height=args.height, frames=args.frames, sort=args.sort, rasterizers=rasterizers,
                       budgets=tuple(args.budget) if args.budget else None,
                       reference_size=None if args.no_reference else tuple(args.reference_size),
                       animate=args.animate, simulate=args.simulate, turn_sh=not args.no_turn_sh)
    print(format_report(result))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)
    return 0
