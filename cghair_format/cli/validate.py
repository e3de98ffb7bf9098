"""``cgh validate FILE [--reference [--cards N]]``: exit 0 if the file decodes and is consistent (and,
with ``--reference``, the slow reference decoder gives the same strands bit for bit), else 1 with the
reason."""

from __future__ import annotations

import argparse

from .argtypes import int_at_least
from .info import animation_line, bound_line, opacity_line


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="a .cgh file")
    p.add_argument("--reference", action="store_true",
                   help="also decode a quantized file's strands (and animation frames) with the reference decoder "
                        "(spec alone, pure Python: 2 CPU minutes, 2.3 GB for 25,000 strands) and check both give "
                        "the same points (and cards), bit for bit")
    p.add_argument("--cards", type=int_at_least(1), default=None, metavar="N",
                   help="with --reference, only the strands of N evenly spaced cards (default: all)")


def run(args: argparse.Namespace) -> int:
    from ..codec import read, read_animation, read_info
    from ..reference_decoder import compare, compare_frames, evenly_spaced_cards

    asset = read(args.file)
    info = read_info(args.file)
    animation = read_animation(args.file)  # every frame, checked
    counts = asset.counts
    points = f"{counts.max()}" if counts.min() == counts.max() else f"{counts.min()}-{counts.max()}"
    print(f"{args.file}: valid .cgh ({asset.n_strands:,} strands of {points} points, {asset.n_gaussians:,} "
          f"Gaussians); points: {bound_line(info)}; opacities: {opacity_line(info)}")
    if animation is not None:
        print(f"{args.file}: animation: {animation_line(info['animation'])}")
    if not args.reference:
        return 0
    if info["quant"]["lossless"]:
        print(f"{args.file}: lossless: it stores its points, so there is nothing for the reference decoder to check")
        return 0
    with open(args.file, "rb") as f:
        data = f.read()
    compared, differ = compare(data, evenly_spaced_cards(asset.cards.count, args.cards))
    if differ:
        print(f"{args.file}: the reference decoder gives other points on {differ:,} of {compared:,} strands")
        return 1
    print(f"{args.file}: the reference decoder gives the same points on all {compared:,} strands, bit for bit")
    if animation is None:
        return 0
    frames, differ = compare_frames(data)
    if differ:
        print(f"{args.file}: the reference decoder gives other cards on {differ:,} of {frames:,} animation frames")
        return 1
    print(f"{args.file}: the reference decoder gives the same cards on all {frames:,} animation frames, bit for bit")
    return 0
