"""``cgh encode IN.cgh -o OUT.cgh --profile P [--point-tolerance F] [--views DATASET]``: re-encode with
another precision profile, its strand points held within ``F`` of the bbox diagonal if given; with a
dataset, the opacities of the Gaussians its training views hardly use may be stored lower (measured by
the training package, which registers that step: ``training.cli_encode_views``)."""

from __future__ import annotations

import argparse

from ..errors import CghError, MissingDependencyError
from ..profiles import DEFAULT_OPACITY_BUDGET, PROFILES
from .argtypes import add_point_tolerance_argument, share, with_point_tolerance
from .info import opacity_line
from .registry import registered

# entry point (group, name) of the step that measures which Gaussians a dataset's views hardly use
VIEWS_STEP = ("cgh.negligible", "views")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="a .cgh file")
    p.add_argument("-o", "--output", required=True, help="the .cgh file to write")
    p.add_argument("--profile", choices=list(PROFILES), default="compact",
                   help="precision profile (default: compact)")
    add_point_tolerance_argument(p)
    p.add_argument("--keep-order", action="store_true",
                   help="keep the input's strand order (default: the writer's order, card by card, which codes "
                        "smaller; the lossless profile always keeps it)")
    p.add_argument("--views", metavar="DATASET",
                   help="a dataset the file was trained on: the Gaussians its training views use least may be stored "
                        "less opaque, down to 0, as cgh train writes them (needs torch; quantized profiles only)")
    p.add_argument("--opacity-budget", type=share, metavar="SHARE", default=None,
                   help=f"with --views: the share of the blend weight those Gaussians carry together (default: "
                        f"{DEFAULT_OPACITY_BUDGET})")


def run(args: argparse.Namespace) -> int:
    from ..codec import read, read_animation, read_info, write

    if args.opacity_budget is not None and args.views is None:
        raise CghError("--opacity-budget needs --views DATASET: the views that measure which Gaussians show")
    if args.views is not None and PROFILES[args.profile].lossless:
        raise CghError("--views lowers opacities, which the lossless profile keeps exact: choose a quantized "
                       "--profile")
    profile = with_point_tolerance(args.profile, args.point_tolerance)
    source = read_info(args.input)
    asset = read(args.input)
    negligible, budget = None, None
    if args.views is not None:
        budget = DEFAULT_OPACITY_BUDGET if args.opacity_budget is None else args.opacity_budget
        negligible = _negligible(asset, args.views, budget)
        print(f"{int(negligible.sum()):,} of {asset.n_gaussians:,} Gaussians carry {budget:g} of the blend "
              f"weight of {args.views}'s training views: their opacities may be stored lower")
    report = write(asset, args.output, profile, keep_order=args.keep_order, negligible=negligible,
                   opacity_budget=budget, animation=read_animation(args.input))
    total = sum(report.chunk_sizes.values())
    bound = "" if profile.lossless else f" (bound {profile.position_tolerance:.3g})"
    print(f"wrote {args.output}: profile {report.profile}, {total:,} bytes of chunks, max point error "
          f"{report.max_point_error:.3g} ({report.max_point_error / max(report.bbox_diagonal, 1e-30):.2e} "
          f"of the bbox diagonal{bound})" + ("" if report.strand_order is None else "; strands stored card by card"))
    if report.opacity is not None:
        print(report.opacity.summary())
    if report.animation is not None:
        print(report.animation.summary(report.bbox_diagonal))
    if not source["quant"]["lossless"]:
        within = source["points_within"]  # (None: a profile of the caller's own, written through the API)
        bound = f"up to {within:.3g} of the bbox diagonal" if within is not None else "a quantization step"
        print(f"note: {args.input} is a {source['profile']} file, so that error is measured against its decoded "
              f"points, which already lie {bound} from the strands it was made from")
        if source["opacities"]["lowered"] is not None:
            print(f"note: {args.input} stores opacities lower ({opacity_line(source)}), and {args.output}'s are "
                  "measured against those")
    return 0


def _negligible(asset, dataset: str, budget: float):
    """The step ``--views`` takes, registered by the package that renders views (the training extra's)."""
    try:
        step = registered(*VIEWS_STEP)
    except ImportError as exc:  # registered, but its package is not there
        raise MissingDependencyError(exc.name or "training", "training", "cgh encode --views") from None
    if step is None:
        raise MissingDependencyError("training", "training", "cgh encode --views")
    return step(asset, dataset, budget)
