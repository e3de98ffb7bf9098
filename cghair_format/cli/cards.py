"""``cgh cards STRANDS -o out.cgh [--cards N] [--groups N]``: build hair cards and write a .cgh.

Prints the per-stage timings and the reconstruction error before quantization (the float asset)
and after it (the written file, read back and decoded).
"""

from __future__ import annotations

import argparse
import sys

from .argtypes import int_at_least, positive_float

PROFILE_NAMES = ("compact", "high", "lossless")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("strands", metavar="STRANDS", help="input strands (.hair .data .tfx .ply .usd* .npz .cgh)")
    p.add_argument("-o", "--output", required=True, help="output .cgh file")
    p.add_argument("--cards", type=int_at_least(1), default=800,
                   help="number of cards N_c (default: 800; capped at the strand count)")
    p.add_argument("--groups", type=int_at_least(1), default=64,
                   help="number of card groups N_T sharing a codebook (default: 64; capped at the card count)")
    p.add_argument("--segments", type=int_at_least(1), default=32, help="segments M per card (default: 32)")
    p.add_argument("--points", type=int_at_least(4), default=None, metavar="N",
                   help="resample every strand to N points (default: keep every strand's own points, of "
                        "varying counts if they vary); the shape error that costs is printed")
    p.add_argument("--sh-degree", type=int, choices=(0, 1, 2, 3), default=3, help="SH degree (default: 3)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the k-means stages (default: 0)")
    p.add_argument("--profile", choices=PROFILE_NAMES, default="compact",
                   help="precision profile of the written file (default: compact)")
    p.add_argument("--keep-order", action="store_true",
                   help="keep the input's strand order in the file (default: the writer's order, which codes smaller)")
    p.add_argument("--units", type=positive_float, default=None,
                   help="metres per input unit (overrides what the file says)")
    p.add_argument("--up", choices=("Y", "Z"), default=None, help="up axis of the input (overrides the file)")
    p.add_argument("--attribution", default=None, help="attribution text stored in the .cgh")
    p.add_argument("--debug-dir", default=None,
                   help="also write the strand textures (PNG) and the card meshes (cards.obj) here")
    p.add_argument("--no-progress", action="store_true", help="no progress bars or per-stage lines")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..cards import build_cards
    from ..codec import read, write
    from ..exchange import load_strands
    from ..profiles import get_profile

    out = Path(args.output)
    if out.suffix.lower() != ".cgh":
        print(f"cgh cards: error: the output must be a .cgh file, got {out}", file=sys.stderr)
        return 2
    strands = load_strands(args.strands, units=args.units, up=args.up)
    build = build_cards(strands, n_cards=args.cards, n_groups=args.groups, segments=args.segments,
                        points=args.points, seed=args.seed, progress=not args.no_progress,
                        sh_degree=args.sh_degree)
    if args.attribution is not None:
        build.asset.attribution = args.attribution
    report = write(build.asset, out, profile=args.profile, keep_order=args.keep_order)
    after = build.error_of(read(out), report)
    info = build.info
    counts = build.asset.counts
    given = f"{info['points']}" if counts.min() == info["points"] else f"{counts.min()}-{info['points']}"
    print(f"{out}: {info['strands']:,} strands x {given} points on {info['cards']:,} cards of "
          f"{args.segments} segments, {info['groups']} groups; {out.stat().st_size:,} bytes ({args.profile})")
    print(build.timing_table(), end="")
    if build.resampling is not None:
        print(build.resampling.line())
        bound = get_profile(args.profile).position_tolerance
        if build.resampling.shape_error > bound:
            print(f"note: that is more than the {args.profile} profile's bound ({bound:.0e}); the errors below are "
                  "measured against the resampled points (leave out --points to keep the input's own)")
    print(build.error.line("point error before quantization"))
    print(after.line(f"point error after quantization ({args.profile})"))
    if build.unsolved_points or build.outside_strip:
        print(f"note: {build.unsolved_points} points had no exact card solution, "
              f"{build.outside_strip} lie outside their card's strip")
    if args.debug_dir:
        from ..cards import write_debug

        paths = write_debug(build, args.debug_dir)
        print("debug: " + ", ".join(str(p) for p in paths))
    return 0
