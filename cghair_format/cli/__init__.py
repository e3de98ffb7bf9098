"""The ``cgh`` command line. Each verb lives in its own module with ``add_arguments`` and ``run``.

Verb modules are imported only when their verb is used, so ``cgh info`` never loads torch or GL.
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

# verb -> (module defining add_arguments(parser) and run(args) -> int, one-line help)
VERBS: dict[str, tuple[str, str]] = {
    "demo": ("cghair_format.cli.demo", "run the main job end to end on built-in data"),
    "info": ("cghair_format.cli.info", "show counts, chunk sizes and bits per Gaussian of a .cgh"),
    "validate": ("cghair_format.cli.validate", "check a .cgh file; exit 0 if valid, 1 with the reason"),
    "encode": ("cghair_format.cli.encode", "re-encode a .cgh with another precision profile"),
    "synth": ("cghair_format.cli.synth", "grow a built-in procedural hairstyle"),
    "convert": ("cghair_format.cli.convert", "convert strands between formats (.cgh accepted as input)"),
    "export": ("cghair_format.cli.export", "export a .cgh or strands to USD, 3DGS PLY, Alembic or .blend"),
    "cards": ("cghair_format.cli.cards", "build hair cards from strands and write a .cgh"),
    "batch": ("batch.cli", "convert, encode and check a library of strand files on Dask, with a report"),
    "render-dataset": ("training.cli_dataset", "render a multi-view dataset of strands"),
    "train": ("training.cli_train", "fit the compact appearance model to a multi-view dataset"),
    "eval": ("training.cli_eval", "PSNR, SSIM and LPIPS of a .cgh on a dataset's held-out views"),
    "ablation": ("training.ablation", "train the paper's appearance variants or codebook sweeps side by side"),
    "reconstruct": ("training.cli_reconstruct", "reconstruct strands from a multi-view dataset with hair masks"),
    "fit-strand-prior": ("training.cli_fit_prior", "fit a PCA basis of strand shapes for cgh reconstruct --prior"),
    "eval-strands": ("training.cli_eval_strands", "position, curvature, F1 of strands vs ground truth"),
    "view": ("viewer.cli", "open a .cgh in an interactive window"),
    "render": ("viewer.cli_render", "render a .cgh to a PNG, GIF or MP4 without a display"),
    "bench-viewer": ("viewer.cli_bench", "measure the viewer's load and frame times"),
}
# verbs whose --output is a folder (made as needed); every other verb's --output is a file
FOLDER_OUTPUTS = {"demo", "render-dataset"}
# verbs that make their --output file's missing folders
PARENTS_MADE = {"train"}
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
    for verb, (module, help_text) in VERBS.items():
        p = sub.add_parser(verb, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        try:
            importlib.import_module(module).add_arguments(p)
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
    args = parser.parse_args(argv)
    if args.verb is None:
        parser.print_help()
        return 2
    set_default_limits(ReadLimits(args.max_gaussians, args.max_decoded_mb << 20))
    if getattr(args, "_unavailable", None):
        print(f"cgh {args.verb}: unavailable: {args._unavailable}", file=sys.stderr)
        return 2
    try:
        if getattr(args, "output", None) is not None:  # before any long work
            check_writable(args.output, folder=args.verb in FOLDER_OUTPUTS, make_parents=args.verb in PARENTS_MADE)
        for option in FOLDER_OPTIONS:
            if getattr(args, option, None) is not None:
                check_writable(getattr(args, option), folder=True)
        with warnings.catch_warnings():  # restores the default hook when main returns (tests call it in-process)
            warnings.showwarning = _show_warning
            return int(importlib.import_module(args._module).run(args) or 0)
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
