"""``cgh encode IN.cgh -o OUT.cgh --profile P``: re-encode with another precision profile."""

from __future__ import annotations

import argparse

from ..profiles import PROFILES


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="a .cgh file")
    p.add_argument("-o", "--output", required=True, help="the .cgh file to write")
    p.add_argument("--profile", choices=list(PROFILES), default="compact",
                   help="precision profile (default: compact)")
    p.add_argument("--keep-order", action="store_true",
                   help="keep the input's strand order (default: the writer's order, card by card, which codes "
                        "smaller; the lossless profile always keeps it)")


def run(args: argparse.Namespace) -> int:
    from ..codec import read, read_info, write

    source = read_info(args.input)
    report = write(read(args.input), args.output, args.profile, keep_order=args.keep_order)
    total = sum(report.chunk_sizes.values())
    print(f"wrote {args.output}: profile {report.profile}, {total:,} bytes of chunks, max point error "
          f"{report.max_point_error:.3g} ({report.max_point_error / max(report.bbox_diagonal, 1e-30):.2e} "
          "of the bbox diagonal)" + ("" if report.strand_order is None else "; strands stored card by card"))
    if not source["quant"]["lossless"]:
        known = PROFILES.get(source["profile"])  # (a profile of the caller's own, written through the API: None)
        bound = (f"up to {known.position_tolerance:.0e} of the bbox diagonal" if known is not None
                 else "a quantization step")
        print(f"note: {args.input} is a {source['profile']} file, so that error is measured against its decoded "
              f"points, which already lie {bound} from the strands it was made from")
    return 0
