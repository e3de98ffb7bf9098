"""``cgh validate FILE``: exit 0 if the file decodes and is consistent, else 1 with the reason."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="a .cgh file")


def run(args: argparse.Namespace) -> int:
    from ..codec import read

    asset = read(args.file)
    print(f"{args.file}: valid .cgh ({asset.n_strands:,} strands, {asset.n_gaussians:,} Gaussians)")
    return 0
