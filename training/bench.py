"""Training speed on this machine, with a per-stage breakdown.

    python -m training.bench --strands ../shared/data/hair/Ratboy_mohawk.tfx --iters 2000 \
        --views 32 --res 128 --points 32 [--threads 1] [--device cuda] [--work bench_out]

Renders a splat dataset if the work folder has none, builds the cards (timed apart), trains the
latents variant and prints iterations per second and the seconds spent per stage. It reports
figures only; it asserts nothing about time.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--strands", required=True)
    p.add_argument("--work", default="bench_out")
    p.add_argument("--iters", type=int, default=2000)
    p.add_argument("--views", type=int, default=32)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--points", type=int, default=32)
    p.add_argument("--n-cards", type=int, default=800)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda (default: cpu)")
    p.add_argument("--engine", choices=("splat", "cycles"), default="splat")
    p.add_argument("--dataset", default=None, help="use this rendered dataset instead of rendering one")
    args = p.parse_args(argv)
    from cghair_format.errors import CghError

    try:
        return _run(args)
    except CghError as exc:
        print(f"bench: error: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    import torch

    from cghair_format.exchange import load_strands

    from .ablation import scaled_config
    from .dataset import render_dataset
    from .evaluate import evaluate
    from .train import base_asset, train

    if args.threads:
        torch.set_num_threads(args.threads)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    ds_dir = Path(args.dataset) if args.dataset else work / f"dataset_{args.engine}_{args.res}"
    strands = load_strands(args.strands)
    if not (ds_dir / "transforms_test.json").is_file():
        render_dataset(strands, ds_dir, views=args.views, res=args.res, engine=args.engine, device=args.device)
    cfg = scaled_config("latents", args.iters, n_cards=args.n_cards, points_per_strand=args.points)
    t = time.perf_counter()
    base = base_asset(cfg, strands, progress=False)
    cards_s = time.perf_counter() - t
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    result = train(ds_dir, cards=base, out=work / "latents.cgh", config=cfg, progress=True, device=args.device)
    ev = evaluate(work / "latents.cgh", ds_dir, use_lpips=False, device=args.device)
    total = sum(result.stage_seconds.values())
    gpu = f", {torch.cuda.get_device_name()}" if args.device.startswith("cuda") else ""
    print(f"machine: {os.cpu_count()} cores{gpu}, torch threads {torch.get_num_threads()}, load average at start "
          f"{load:.2f}, at end {os.getloadavg()[0]:.2f}")
    print(f"scene: {base.n_strands} strands x {base.points_per_strand} points = {base.n_gaussians} Gaussians, "
          f"{args.views} views at {args.res} x {args.res}")
    print(f"cards: {cards_s:.1f} s; training: {result.iterations_run} iterations in {result.seconds:.1f} s "
          f"({result.iterations_run / result.seconds:.2f} it/s)")
    for name, sec in result.stage_seconds.items():
        per_it = 1000 * sec / max(1, result.iterations_run)
        print(f"  {name:<9}{sec:8.1f} s  {100 * sec / total:5.1f} %  {per_it:7.1f} ms/it")
    print(f"held-out: PSNR {ev.psnr:.2f} dB, SSIM {ev.ssim:.4f} ({args.engine} ground truth)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
