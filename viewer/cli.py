"""``cgh view FILE.cgh``: open a .cgh in an interactive window."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="the .cgh file to open")
    parser.add_argument("--width", type=int, default=1280, help="window width in pixels (default 1280)")
    parser.add_argument("--height", type=int, default=720, help="window height in pixels (default 720)")
    parser.add_argument("--sort", choices=("auto", "gpu", "cpu"), default="auto",
                        help="depth sort: GPU radix sort, numpy, or auto (GPU except on software renderers)")
    add_raster_arguments(parser, budget_help="a fixed splat budget, e.g. 500k (default: adaptive, full quality "
                         "when the camera rests; key B cycles budgets)")
    parser.add_argument("--simulate", action="store_true",
                        help="run the strand simulation live: ctrl-drag turns the head, ctrl-right-drag moves it "
                             "(an animated file otherwise plays its animation: space, arrows, page up/down)")
    add_turn_argument(parser)
    parser.add_argument("--screenshots", default=".", help="folder for screenshots (key P)")
    parser.add_argument("--frames", type=int, default=None, help="close after this many frames (scripted runs)")
    parser.add_argument("--press", default="", metavar="KEYS",
                        help="key presses to replay before the first frame, e.g. 'LGP', or key names separated "
                             "by commas, e.g. 'SPACE,RIGHT,P' (scripted runs)")


def press_keys(text: str) -> tuple[str, ...]:
    """``--press``: one key a character, or key names (``SPACE``, ``RIGHT``) separated by commas."""
    return tuple(k.strip().upper() for k in text.split(",") if k.strip()) if "," in text else tuple(text)


def budget_type(text: str) -> int:
    """argparse type of ``--budget``: a positive number of Gaussians (``250000``, ``250k``, ``2.5M``)."""
    from .lod import parse_budget

    try:
        return parse_budget(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_raster_arguments(parser: argparse.ArgumentParser, budget_help: str, rasterizers=("auto", "compute", "raster"),
                         default: str = "auto", many_budgets: bool = False) -> None:
    """``--rasterizer`` and ``--budget``, shared by ``view``, ``render`` and ``bench-viewer``."""
    parser.add_argument("--rasterizer", choices=rasterizers, default=default,
                        help="compute: tiles in compute shaders with early termination; raster: one triangle per "
                             "splat, fixed-function blending; auto: compute where OpenGL 4.3 compute shaders exist, "
                             f"else raster (default {default})")
    parser.add_argument("--budget", type=budget_type, default=None, metavar="N", nargs="+" if many_budgets else None,
                        help=budget_help)


def add_turn_argument(parser: argparse.ArgumentParser) -> None:
    """``--no-turn-sh``, shared by ``view``, ``render`` and ``bench-viewer``."""
    parser.add_argument("--no-turn-sh", action="store_true",
                        help="hair that moves: leave each Gaussian's SH as at rest instead of turning them with its "
                             "segment (for comparison)")


def positive(parser_name: str, value: int) -> None:
    from cghair_format.errors import CghError

    if value < 1 or value > 16384:
        raise CghError(f"--{parser_name} must be between 1 and 16384, got {value}")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import cghair_format
    from cghair_format.errors import CghError

    from .app import run_viewer
    from .motion import file_animation

    positive("width", args.width)
    positive("height", args.height)
    if args.frames is not None and args.frames < 1:
        raise CghError(f"--frames must be >= 1, got {args.frames}")
    if not Path(args.screenshots).is_dir():
        raise CghError(f"screenshot folder {args.screenshots} does not exist")
    asset = cghair_format.read(args.file)
    animation = None if args.simulate else file_animation(args.file)
    run_viewer(asset, title=f"cgh view {Path(args.file).name}", file_size=Path(args.file).stat().st_size,
               width=args.width, height=args.height, sort=args.sort, rasterizer=args.rasterizer,
               budget=args.budget, screenshot_dir=args.screenshots,
               max_frames=args.frames, press=press_keys(args.press), animation=animation, simulate=args.simulate,
               turn_sh=not args.no_turn_sh)
    return 0
