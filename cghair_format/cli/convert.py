"""``cgh convert IN OUT``: strands from one format to another (a .cgh is read as its decoded strands).

Optional processing on the way: ``--points N`` resamples every strand to N points
(``--method arclength|bspline``), ``--densify N`` adds interpolated strands up to N strands,
``--units`` / ``--up`` override the metres per unit and up axis of the input; ``--scale`` multiplies
the output's coordinates and widths (its units shrink alike); ``--smooth MM`` low-passes every strand
along its length first (:mod:`cghair_format.smooth`, as ``cgh reconstruct --smooth`` does).
"""

from __future__ import annotations

import argparse

from .argtypes import non_negative_float, positive_float
from .synth import _at_least_two, _positive


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="strand file (.hair .data .tfx .ply .usd .usda .usdc .usdz .npz) or .cgh")
    p.add_argument("output", help="output strand file (.hair .data .tfx .ply .usd .usda .usdc .usdz .npz)")
    p.add_argument("--points", type=_at_least_two, help="resample every strand to this many points")
    p.add_argument("--method", choices=("arclength", "bspline"), default="arclength",
                   help="resampling method for --points (default: arclength)")
    p.add_argument("--densify", type=_positive, metavar="N",
                   help="add strands interpolated between scalp neighbours up to N strands")
    p.add_argument("--seed", type=int, default=0, help="random seed for --densify (default: 0)")
    p.add_argument("--units", type=float, metavar="M", help="metres per unit of the input (overrides the file)")
    p.add_argument("--up", choices=("Y", "Z", "y", "z"), help="up axis of the input (overrides the file)")
    p.add_argument("--scale", type=positive_float, default=1.0, metavar="S",
                   help="multiply output coordinates and widths by S; the units shrink alike (100: metres to cm)")
    p.add_argument("--smooth", type=non_negative_float, default=0.0, metavar="MM",
                   help="low-pass every strand along its length with a Gaussian of MM millimetres (by the "
                        "input's units), root and length kept, before --points (default: 0, none)")
    p.add_argument("--points-per-strand", type=_at_least_two, metavar="P",
                   help="point count of vertex-only strand PLY input (GaussianHaircut layout)")


def run(args: argparse.Namespace) -> int:
    from ..exchange import load_strands, save_strands
    from ..exchange._common import scale_strands
    from ..smooth import smooth_strands
    from ..strands import densify, resample

    strands = load_strands(args.input, units=args.units, up=args.up, points_per_strand=args.points_per_strand)
    n_in = strands.count
    strands = smooth_strands(strands, args.smooth)
    if args.points:
        strands = resample(strands, args.points, args.method)
    if args.densify:
        strands = densify(strands, args.densify, seed=args.seed, n_points=args.points)
    save_strands(scale_strands(strands, args.scale), args.output)
    counts = strands.point_counts
    pts = f"{counts.min()}" if counts.min() == counts.max() else f"{counts.min()}..{counts.max()}"
    print(f"{args.input} -> {args.output}: {n_in:,} -> {strands.count:,} strands x {pts} points")
    return 0
