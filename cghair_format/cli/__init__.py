"""The ``cgh`` command line. Each verb lives in its own module with ``add_arguments`` and ``run``; the
format's verbs and those the packages above it register are listed by :mod:`.registry`.

Verb modules import their heavy packages only when their verb runs, so ``cgh info`` never loads torch or GL.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

from ..atomic import check_writable
from ..errors import CghError
from ..limits import ReadLimits, set_default_limits
from .argtypes import int_at_least
from .registry import Verb, verbs

# other options that name a folder a verb writes into (cgh eval --out, cgh cards --debug-dir, cgh ablation --work)
FOLDER_OPTIONS = ("out", "debug_dir", "work")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cgh", description="CGHair: compact Gaussian hair assets (.cgh).")
    limits = ReadLimits()
    parser.add_argument("--max-gaussians", type=int_at_least(1), default=limits.max_gaussians, metavar="N",
                        help=f"largest Gaussian count a .cgh may hold to be read (default: {limits.max_gaussians:,})")
    parser.add_argument("--max-decoded-mb", type=int_at_least(1), default=limits.max_decoded_bytes >> 20,
                        metavar="MB", help="largest memory decoding a .cgh may take, in MiB (default: "
                        f"{limits.max_decoded_bytes >> 20:,})")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for name, verb in verbs().items():
        p = sub.add_parser(name, help=verb.help, description=verb.help)
        p.set_defaults(_verb=verb)
        try:
            importlib.import_module(verb.module).add_arguments(p)
        except ImportError as exc:
            p.set_defaults(_unavailable=str(exc))
    return parser


def format_warning(message: Warning | str) -> str:
    """A warning as the CLI prints it: one line, no category, source file or source line."""
    return "cgh: warning: " + " ".join(str(message).split())


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(format_warning(message), file=file if file is not None else sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)  # a verb that cannot load has no arguments to know
    if unknown and not getattr(args, "_unavailable", None):
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")  # as parse_args says it
    if args.verb is None:
        parser.print_help()
        return 2
    set_default_limits(ReadLimits(args.max_gaussians, args.max_decoded_mb << 20))
    if getattr(args, "_unavailable", None):
        print(f"cgh {args.verb}: unavailable: {args._unavailable}", file=sys.stderr)
        return 2
    try:
        verb: Verb = args._verb
        if getattr(args, "output", None) is not None:  # before any long work
            check_writable(args.output, folder=verb.output_folder, make_parents=verb.make_parents)
        for option in FOLDER_OPTIONS:
            if getattr(args, option, None) is not None:
                check_writable(getattr(args, option), folder=True)
        with warnings.catch_warnings():  # restores the default hook when main returns (tests call it in-process)
            warnings.showwarning = _show_warning
            return int(importlib.import_module(verb.module).run(args) or 0)
    except CghError as exc:
        print(f"cgh {args.verb}: error: {exc}", file=sys.stderr)
        return 1 if args.verb == "validate" else 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"cgh {args.verb}: error: {exc.strerror}: {exc.filename}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cgh {args.verb}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a reader that stopped early (e.g. `| head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
