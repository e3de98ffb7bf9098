"""``cgh train DIR --strands STRANDS -o out.cgh [--iters N] [--variant ...]``.

Builds cards from the strands (or takes a .cgh with cards), fits the appearance model to the
dataset's training views, checkpoints every ``--checkpoint-every`` iterations (``--resume``
continues), and writes the .cgh, ``<out>.train.json`` (config and figures) and ``<out>.ckpt.pt``.
"""

from __future__ import annotations

import argparse
import sys

from cghair_format.cli.argtypes import (
    add_point_tolerance_argument,
    int_at_least,
    non_negative_float,
    share,
    with_point_tolerance,
)
from cghair_format.profiles import DEFAULT_OPACITY_BUDGET

from .config import BACKENDS, VARIANTS

PROFILE_NAMES = ("compact", "high", "lossless")
FROZEN_FRACTION = 7_000 / 30_000  # the paper's geometry freeze, as a fraction of the run


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", metavar="DIR", help="dataset folder: NeRF-synthetic (cgh render-dataset), COLMAP "
                   "or GaussianHaircut layout, told apart by the files present")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--strands", help="strands to build cards from (any format cgh convert reads)")
    src.add_argument("--cards", help="a .cgh whose cards and strand coordinates to start from")
    p.add_argument("-o", "--output", required=True, help="output .cgh file")
    p.add_argument("--iters", type=int_at_least(1), default=None,
                   help="iterations (default: 30000, the paper's; a shorter run keeps the paper's proportion of "
                        "frozen geometry, 7k of 30k)")
    p.add_argument("--geometry-frozen-iters", type=int_at_least(0), metavar="ITERS", default=None,
                   help="iterations before the strand points start to move (default: 7/30 of --iters, the paper's "
                        "proportion); as many as --iters keeps the given strands as they are, and the file small "
                        "(docs/ablation.md, 'The trained file')")
    p.add_argument("--geometry-rate", type=non_negative_float, metavar="W", default=None,
                   help="while the strand points move, add W times the strand coder's estimated bits per stored "
                        "coordinate to the loss, which keeps the moved strands cheap to store (default: 0, off; "
                        "docs/training.md, 'Rate-aware geometry')")
    p.add_argument("--geometry-controls", type=int_at_least(0), metavar="N", default=None,
                   help="move each strand by a smooth correction only, a cubic B-spline of N coefficients over its "
                        "points, which keeps the moved strands about as cheap to store as the given ones (default: 0, "
                        "off: every point moves on its own; docs/training.md, 'Smooth moves')")
    p.add_argument("--free-children", action="store_true",
                   help="move every strand on its own, the interpolated ones (children) too; by default the strands "
                        "the file stores as blends of others follow those, and stay a few bytes each "
                        "(docs/training.md, 'Children follow their guides')")
    p.add_argument("--variant", choices=VARIANTS, default=None,
                   help="appearance model (default: latents, the paper's); others are the ablation's")
    p.add_argument("--config", help="a JSON config (as saved in <out>.train.json's 'config'); flags override it")
    p.add_argument("--resume", metavar="CKPT", help="continue from a checkpoint (<out>.ckpt.pt)")
    p.add_argument("--checkpoint-every", type=int_at_least(1), default=None,
                   help="checkpoint period in iterations (default: 1000)")
    p.add_argument("--n-cards", type=int_at_least(1), default=None, help="cards to build (default: 800)")
    p.add_argument("--groups", type=int_at_least(1), default=None, help="card groups N_T (default: 64)")
    p.add_argument("--points", type=int_at_least(4), default=None,
                   help="points per strand after resampling (default: 32)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: 0)")
    p.add_argument("--profile", choices=PROFILE_NAMES, default="compact", help="precision of the written .cgh")
    add_point_tolerance_argument(p)
    add_opacity_budget_argument(p)
    p.add_argument("--threads", type=int_at_least(1), default=None,
                   help="torch CPU threads (default: torch's choice; 1 is faster on a busy machine)")
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda (default: cpu)")
    add_backend_argument(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def add_opacity_budget_argument(p: argparse.ArgumentParser) -> None:
    """``--opacity-budget``, shared by the commands that write a trained .cgh."""
    p.add_argument("--opacity-budget", type=share, metavar="SHARE", default=None,
                   help="the Gaussians that together carry this share of the training views' blend weight, the "
                        "least used, may be stored less opaque, down to 0, which codes them for almost nothing "
                        f"(default: {DEFAULT_OPACITY_BUDGET}; 0 keeps every opacity within the profile's bound; "
                        "quantized profiles only; docs/ablation.md, 'Negligible opacities')")


def add_backend_argument(p: argparse.ArgumentParser) -> None:
    """``--backend``, shared by every command that rasterizes."""
    p.add_argument("--backend", choices=BACKENDS, default=None,
                   help="rasterizer (default: native on the CPU when built, gsplat on CUDA when installed, else "
                        "reference; see the README's 'Training backends')")


def _config(args: argparse.Namespace):
    import json
    from pathlib import Path

    from .config import ConfigError, TrainConfig

    if args.config:
        try:
            data = json.loads(Path(args.config).read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{args.config}: not valid JSON ({exc})") from exc
        cfg = TrainConfig.from_dict(data.get("config", data) if isinstance(data, dict) else data)
    else:
        cfg = TrainConfig()
    for flag, name in (("iters", "iterations"), ("variant", "variant"), ("checkpoint_every", "checkpoint_every"),
                       ("n_cards", "n_cards"), ("groups", "n_groups"), ("points", "points_per_strand"),
                       ("seed", "seed"), ("opacity_budget", "opacity_budget"),
                       ("geometry_rate", "geometry_rate"), ("geometry_controls", "geometry_controls")):
        value = getattr(args, flag)
        if value is not None:
            setattr(cfg, name, value)
    if args.iters is not None and not args.config and cfg.geometry_frozen_iters >= args.iters:
        # a short run keeps the paper's proportion (7k of 30k iterations) of frozen geometry
        cfg.geometry_frozen_iters = round(FROZEN_FRACTION * args.iters)
    if args.geometry_frozen_iters is not None:
        cfg.geometry_frozen_iters = args.geometry_frozen_iters
    if args.free_children:
        cfg.children_follow = False
    return cfg.validate()


def _resolve_backend(name: str | None, device: str) -> str:
    """The backend to train with; on CUDA without ``--backend``, says why gsplat is not the one."""
    from .backends import BackendError, check_backend, resolve_backend
    from .splatter import torch_device

    backend = resolve_backend(name, device)
    if name is None and backend == "reference" and torch_device(device).type == "cuda":
        try:
            check_backend("gsplat", device)
        except BackendError as exc:
            print(f"note: training with the reference backend, not gsplat: {exc}", file=sys.stderr)
    return backend


def run(args: argparse.Namespace) -> int:
    from .datasets.layouts import detect_layout
    from .train import TrainError, train

    if not (args.strands or args.cards or args.resume):
        raise TrainError("give --strands (to build cards) or --cards (a .cgh), or --resume a checkpoint")
    cfg = _config(args)
    profile = with_point_tolerance(args.profile, args.point_tolerance)
    _resolve_backend(args.backend, args.device)  # a backend that cannot run here fails before the dataset is read
    print(f"reading {args.dataset}: {detect_layout(args.dataset).describe()}")
    result = train(args.dataset, strands=args.strands, cards=args.cards, out=args.output, config=cfg,
                   resume=args.resume, profile=profile, progress=not args.no_progress,
                   threads=args.threads, device=args.device, backend=args.backend)
    final = result.history[-1] if result.history else None
    if final:
        print(f"iteration {final['iteration']}: loss {final['loss']:.4f}, train PSNR {final['psnr']:.2f} dB "
              f"({result.seconds:.1f} s, {result.iterations_run} iterations this run, backend {result.backend})")
    if result.asset is None:
        why = result.model.export_refusal() or f"variant {cfg.variant!r} has no .cgh encoding"
        print(f"no .cgh written: {why}; wrote {result.out_path.with_suffix('.ckpt.pt')}"
              f" and {result.out_path.with_suffix('.train.json')}", file=sys.stderr)
        return 0
    from cghair_format import read_info
    from cghair_format.cli.info import mlp_line, opacity_line, points_line

    from .train import EXPORT_PROBE_VIEWS

    mode, other = result.weight_mode, "soft" if result.weight_mode == "hard" else "hard"
    print(f"wrote {args.output}: export PSNR {result.export_psnr[mode]:.2f} dB, this file as decoded ({mode} "
          f"weights, opacities as stored) on up to {EXPORT_PROBE_VIEWS} training views; with {other} weights "
          f"{result.export_psnr[other]:.2f} dB")
    info = read_info(args.output)
    print(f"points: {points_line(info)}")
    print(f"opacities: {opacity_line(info)}")
    print(f"MLP {'->'.join(map(str, [info['latent_dim'], *info['mlp']]))}: {mlp_line(info['mlp_weights'])}")
    return 0
