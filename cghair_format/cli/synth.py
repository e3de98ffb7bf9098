"""``cgh synth -o OUT --style S --strands N --points P --seed K``: grow a built-in hairstyle."""

from __future__ import annotations

import argparse

STYLE_NAMES = ("straight", "wavy", "curly", "coily", "short", "long", "ponytail")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", required=True,
                   help="output strand file (.npz .ply .hair .data .tfx .usd .usda .usdc .usdz)")
    p.add_argument("--style", choices=STYLE_NAMES, default="straight", help="hairstyle (default: straight)")
    p.add_argument("--strands", type=_positive, default=10_000, help="number of strands (default: 10000)")
    p.add_argument("--points", type=_at_least_two, default=64, help="points per strand (default: 64)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--multitone", action="store_true",
                   help="dyed lighter tips and contrasting streaks (multi-tone along strands)")


def _positive(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v


def _at_least_two(text: str) -> int:
    v = int(text)
    if v < 2:
        raise argparse.ArgumentTypeError(f"must be at least 2, got {v}")
    return v


def run(args: argparse.Namespace) -> int:
    from ..exchange import save_strands
    from ..synth import synthesize

    strands = synthesize(args.style, args.strands, args.points, args.seed, multitone=args.multitone)
    save_strands(strands, args.output)
    print(f"{args.output}: {strands.count:,} {args.style} strands x {args.points} points "
          f"(seed {args.seed}{', multitone' if args.multitone else ''}), metres, y up")
    return 0
