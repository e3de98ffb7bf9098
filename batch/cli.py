"""``cgh batch MANIFEST_OR_FOLDER -o OUT_DIR``: a library of strand files through import, cards, encode,
round-trip check and exports on Dask, with a per-file report; ``cgh batch --report OUT_DIR`` summarizes a
run's report again and draws its plot. docs/batch.md has the manifest, the outputs and the figures."""

from __future__ import annotations

import argparse
from pathlib import Path

from cghair_format.cli.argtypes import int_at_least, positive_float
from cghair_format.errors import CghError

from .options import EXPORTS, FileOptions


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("manifest", nargs="?", metavar="MANIFEST_OR_FOLDER",
                   help="a folder of strand files, or a .csv / .json list of them with per-file options")
    p.add_argument("-o", "--out", metavar="OUT_DIR", help="output folder: the inputs' tree of outputs, the report")
    p.add_argument("--report", metavar="OUT_DIR", help="summarize the report of an earlier run in OUT_DIR and draw "
                                                       "its plot (OUT_DIR/report.png); runs nothing")
    p.add_argument("--glob", default="**/*", help="with a folder: which files (default: every file a strand "
                                                  "loader reads, in every subfolder)")
    p.add_argument("--profiles", default="compact", help="profiles to encode, comma-separated (default: compact)")
    p.add_argument("--cards", type=int_at_least(1), default=None,
                   help="cards a file (default: one per 30 strands, at most 800)")
    p.add_argument("--groups", type=int_at_least(1), default=None, help="card groups (default: min(cards, 64))")
    p.add_argument("--points", type=int_at_least(4), default=None, metavar="N",
                   help="resample every strand to N points (default: keep each strand's own)")
    p.add_argument("--no-check", dest="check", action="store_false",
                   help="skip the round trip (decode, error against the input's points)")
    p.add_argument("--export", action="append", choices=EXPORTS, default=[], metavar="EXT",
                   help=f"also export the first profile's file as EXT ({', '.join(EXPORTS)}); repeatable")
    p.add_argument("--dataset", default=None, help="train the appearance on this dataset folder (every file)")
    p.add_argument("--iters", type=int_at_least(1), default=300, help="training iterations (default: 300)")
    p.add_argument("--scheduler", "--address", dest="scheduler", metavar="ADDRESS", default=None,
                   help="an existing Dask scheduler (tcp://host:8786); default: a local cluster")
    p.add_argument("--workers", type=int_at_least(1), default=2, help="local cluster's worker processes (default: 2)")
    p.add_argument("--memory-per-task", type=int_at_least(64), default=4096, metavar="MB",
                   help="memory a file may take above its worker's, MiB (default: 4096)")
    p.add_argument("--time-per-task", type=positive_float, default=3600.0, metavar="S",
                   help="seconds a file may take (default: 3600)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from . import Limits, draw_report, format_summary, read_manifest, read_report, run_batch, summarize

    if args.report is not None:
        if args.manifest is not None or args.out is not None:
            raise CghError("--report OUT_DIR reads an earlier run's report; give no manifest and no -o with it")
        folder = Path(args.report)
        rows, summary = read_report(folder)
        summary = summarize(rows, {k: v for k, v in summary.items() if not isinstance(v, dict)})
        print(format_summary(summary))
        print(f"plot: {draw_report(rows, folder / 'report.png')}")
        return 0
    if args.manifest is None or args.out is None:
        raise CghError("give a folder or manifest and -o OUT_DIR (or --report OUT_DIR)")
    defaults = FileOptions(profiles=tuple(p.strip() for p in args.profiles.split(",") if p.strip()),
                           cards=args.cards, groups=args.groups, points=args.points, check=args.check,
                           exports=tuple(args.export), dataset=args.dataset, iters=args.iters)
    jobs = read_manifest(args.manifest, defaults, glob=args.glob, exclude=args.out)
    rows, summary = run_batch(jobs, args.out, scheduler=args.scheduler, workers=args.workers,
                              limits=Limits(args.memory_per_task, args.time_per_task), progress=not args.no_progress)
    print(format_summary(summary))
    print(f"report: {Path(args.out) / 'report.csv'} (and .json, summary.json, report.png)")
    return 1 if summary["failed"] else 0
