"""``cgh bench-viewer``: the viewer's load time and per-frame preprocess, sort and draw times,
next to a bare instanced-quad draw of the same splats in the same run."""

from __future__ import annotations

import argparse


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
    result = benchmark(path=args.file, synthetic=args.synthetic, points=args.points, width=args.width,
                       height=args.height, frames=args.frames, sort=args.sort)
    print(format_report(result))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)
    return 0
