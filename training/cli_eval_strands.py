"""``cgh eval-strands RECON GROUND_TRUTH [--json]``: position and curvature errors and
precision / recall / F1 at 2 mm / 20 deg, 3 mm / 30 deg and 4 mm / 40 deg."""

from __future__ import annotations

import argparse

from cghair_format.cli.argtypes import positive_float


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recon", metavar="RECON", help="reconstructed strands (any format cgh convert reads)")
    p.add_argument("gt", metavar="GROUND_TRUTH", help="ground-truth strands")
    p.add_argument("--meters-per-unit", type=positive_float, default=None,
                   help="scale of both files, overriding what they state (default: each file's own)")
    p.add_argument("--step-mm", type=positive_float, default=None,
                   help="resampling step along the strands in millimetres (default: 1)")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")


def run(args: argparse.Namespace) -> int:
    import json

    from cghair_format.exchange import load_strands

    from .reconstruct.metrics import DEFAULT_STEP_MM, evaluate_strands

    recon, gt = load_strands(args.recon), load_strands(args.gt)
    m = evaluate_strands(recon, gt, step_mm=args.step_mm or DEFAULT_STEP_MM, meters_per_unit=args.meters_per_unit)
    if args.json:
        print(json.dumps(m.to_dict(), indent=2))
        return 0
    scales = (f"{args.meters_per_unit} m per unit (given)" if args.meters_per_unit else
              f"{recon.meters_per_unit:g} and {gt.meters_per_unit:g} m per unit (from the files)")
    print(f"{args.recon} ({recon.count} strands) against {args.gt} ({gt.count} strands), {scales}, "
          f"resampled every {m.step_mm:g} mm: {m.recon_points} and {m.gt_points} points")
    print(m.summary())
    return 0
