"""Reproduce the paper's ablation table: PSNR / SSIM on held-out views, appearance size and ratio.

    python -m training.ablation --strands ../shared/data/hair/Ratboy_mohawk.tfx --work ablation_out \
        --iters 1000 --views 32 --res 128 [--engine cycles|splat] [--variants latents,unique,...]

Renders the dataset once (Cycles by default; ``--engine splat`` when bpy is missing, and the
table says so), builds the cards once, trains every variant from the same cards with the same
schedule, and prints one table row per variant; ``ablation.json`` keeps everything. Quality is
measured from the torch model (the free-SH variants have no .cgh); for the variants with a .cgh
the written file's figures are printed too.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from .cli_train import add_backend_argument
from .config import VARIANTS, TrainConfig

PAPER_NOTE = ("paper (CGHair, CVPR 2026, as quoted in our brief): latents within 1.6 dB PSNR of unique, "
              "with appearance parameters >= 200 x smaller")
FROZEN_FRACTION = 7_000 / 30_000  # the paper's geometry freeze, as a fraction of the run


def scaled_config(variant: str, iters: int, **overrides) -> TrainConfig:
    """The paper's config for a shorter run: the schedules (geometry freeze, temperature, decay)
    keep their proportions."""
    cfg = TrainConfig(variant=variant, iterations=iters, geometry_frozen_iters=round(FROZEN_FRACTION * iters),
                      checkpoint_every=max(1, iters), log_every=max(1, iters // 20))
    for key, value in overrides.items():
        setattr(cfg, key, value)
    return cfg.validate()


def run_ablation(strands_path: str, work: Path, iters: int, views: int, res: int, engine: str,
                 variants: list[str], samples: int, threads: int | None, n_cards: int, points: int,
                 dataset: Path | None = None, log=sys.stderr, device: str = "cpu",
                 backend: str | None = None) -> list[dict]:
    import torch

    from cghair_format.exchange import load_strands

    from .backends import resolve_backend
    from .dataset import read_dataset, render_dataset
    from .evaluate import evaluate, evaluate_model
    from .model import tau_at
    from .train import base_asset, train

    if threads:
        torch.set_num_threads(threads)
    backend = resolve_backend(backend, device)
    work.mkdir(parents=True, exist_ok=True)
    ds_dir = dataset if dataset is not None else work / f"dataset_{engine}"
    strands = load_strands(strands_path)
    if not (ds_dir / "transforms_test.json").is_file():
        t = time.perf_counter()
        render_dataset(strands, ds_dir, views=views, res=res, engine=engine, samples=samples, progress=True,
                       device=device, backend=backend)
        print(f"rendered {views} views with {engine} in {time.perf_counter() - t:.1f} s", file=log)
    ds = read_dataset(ds_dir)
    base = base_asset(scaled_config("latents", iters, n_cards=n_cards, points_per_strand=points), strands,
                      progress=False)
    rows = []
    for variant in variants:
        cfg = scaled_config(variant, iters, n_cards=n_cards, points_per_strand=points)
        out = work / f"{variant}.cgh"
        result = train(ds, cards=base, out=out, config=cfg, progress=True, log=log, device=device, backend=backend)
        tau = tau_at(cfg, cfg.iterations)
        mode = result.weight_mode or "soft"
        ev = evaluate_model(result.model, ds.test, mode, tau, out_dir=work / f"{variant}_test", backend=backend)
        row = {"variant": variant, "psnr": ev.psnr, "ssim": ev.ssim,
               "appearance_bytes": result.model.appearance_bytes(), "seconds": result.seconds,
               "iterations": cfg.iterations, "weight_mode": result.weight_mode,
               "train_psnr": result.history[-1]["psnr"] if result.history else None}
        if result.asset is not None:
            fev = evaluate(out, ds, use_lpips=False, device=device, backend=backend)
            row.update(file_psnr=fev.psnr, file_ssim=fev.ssim, file_bytes=out.stat().st_size)
        rows.append(row)
        print(f"{variant}: test PSNR {ev.psnr:.2f} dB, SSIM {ev.ssim:.4f}", file=log)
    unique = next((r for r in rows if r["variant"] == "unique"), None)
    for r in rows:
        r["ratio_vs_unique"] = unique["appearance_bytes"] / r["appearance_bytes"] if unique else None
    (work / "ablation.json").write_text(json.dumps({
        "strands": strands_path, "engine": engine, "backend": backend, "views": views, "res": res, "iterations": iters,
        "gaussians": base.n_gaussians, "strands_count": base.n_strands, "rows": rows}, indent=2) + "\n")
    return rows


def table(rows: list[dict], engine: str) -> str:
    lines = [f"ablation on {engine}-rendered held-out views",
             "| variant | PSNR (dB) | SSIM | appearance | ratio vs unique | .cgh PSNR | .cgh size |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f"{r['ratio_vs_unique']:.1f} x" if r.get("ratio_vs_unique") else "-"
        fp = f"{r['file_psnr']:.2f}" if "file_psnr" in r else "n/a (no .cgh encoding)"
        fb = f"{r['file_bytes'] / 1024:.0f} KiB" if "file_bytes" in r else "-"
        lines.append(f"| {r['variant']} | {r['psnr']:.2f} | {r['ssim']:.4f} | "
                     f"{r['appearance_bytes'] / 1024:.0f} KiB | {ratio} | {fp} | {fb} |")
    lines.append(PAPER_NOTE)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.ablation", description=__doc__.split("\n\n")[0])
    p.add_argument("--strands", required=True, help="a real hair model, e.g. ../shared/data/hair/Ratboy_mohawk.tfx")
    p.add_argument("--work", default="ablation_out", help="output folder (dataset, .cgh files, ablation.json)")
    p.add_argument("--iters", type=int, default=1000)
    p.add_argument("--views", type=int, default=32)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--engine", choices=("cycles", "splat"), default="cycles")
    p.add_argument("--dataset", default=None, help="use this rendered dataset instead of rendering one")
    p.add_argument("--samples", type=int, default=32)
    p.add_argument("--variants", default=",".join(VARIANTS))
    p.add_argument("--n-cards", type=int, default=800)
    p.add_argument("--points", type=int, default=32)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda (default: cpu)")
    add_backend_argument(p)
    args = p.parse_args(argv)
    variants = [v for v in args.variants.split(",") if v]
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        p.error(f"unknown variants {bad}; choose from {', '.join(VARIANTS)}")
    from cghair_format.errors import CghError

    try:
        rows = run_ablation(args.strands, Path(args.work), args.iters, args.views, args.res, args.engine,
                            variants, args.samples, args.threads, args.n_cards, args.points,
                            Path(args.dataset) if args.dataset else None, device=args.device, backend=args.backend)
    except CghError as exc:
        print(f"ablation: error: {exc}", file=sys.stderr)
        return 2
    print(table(rows, args.engine))
    return 0


if __name__ == "__main__":
    sys.exit(main())
