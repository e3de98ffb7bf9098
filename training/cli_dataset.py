"""``cgh render-dataset STRANDS -o DIR --views N --res R --engine cycles|splat``.

Writes a NeRF-synthetic dataset (transforms_train/val/test.json + RGBA PNGs, alpha = hair mask). The
paper's scale (docs/ablation.md): ``--resample 100 --densify 25000 --engine cycles --views 64
--res 256 --denoise``, and ``--multitone 3`` for its multi-tone synthetic case.
"""

from __future__ import annotations

import argparse

from cghair_format.cli.argtypes import int_at_least, positive_float

from .cli_train import add_backend_argument

ENGINES = ("splat", "cycles")
PRESETS = ("brown", "black", "blonde", "red")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("strands", metavar="STRANDS", help="input strands (.hair .data .tfx .ply .usd* .npz .cgh)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output dataset folder")
    p.add_argument("--views", type=int_at_least(2), default=32, help="number of views (default: 32; every "
                   "8th is held out for testing, every 8th from the 4th for validation)")
    p.add_argument("--res", type=int_at_least(8), default=128, help="image width and height (default: 128)")
    p.add_argument("--engine", choices=ENGINES, default="splat",
                   help="splat: our splatter from a known appearance (fast); cycles: Blender Cycles with the "
                        "Principled Hair BSDF (needs bpy, the 'blender' extra)")
    p.add_argument("--preset", choices=PRESETS, default="brown",
                   help="hair colour when the strands carry none (default: brown)")
    p.add_argument("--samples", type=int_at_least(1), default=16, help="Cycles samples per pixel (default: 16)")
    p.add_argument("--thickness", type=positive_float, default=None,
                   help="strand radius in scene units (default: the card builder's rule)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the colour variation and of Cycles' sampling (default: 0)")
    p.add_argument("--resample", type=int_at_least(2), default=None, metavar="POINTS",
                   help="resample every strand to POINTS points along a cubic B-spline first (the paper: 100)")
    p.add_argument("--densify", type=int_at_least(1), default=None, metavar="STRANDS",
                   help="then interpolate new strands between scalp neighbours up to STRANDS (the paper: 25000)")
    p.add_argument("--multitone", type=int, choices=(2, 3, 4), nargs="?", const=3, default=0, metavar="TONES",
                   help="colour every strand in TONES segments along its length (2-4, default 3), the paper's "
                        "multi-tone synthetic case")
    p.add_argument("--denoise", action="store_true", help="Cycles: run OpenImageDenoise on every view")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--device", default="cpu", help="torch device of the splat engine, e.g. cpu or cuda (default: cpu)")
    add_backend_argument(p)


def run(args: argparse.Namespace) -> int:
    from cghair_format.exchange import load_strands

    from .datasets.synthetic import prepare_strands, render_dataset

    # densified with seed 0, as the benchmarks' paper-scale asset (tests/bench/paper_scale.py): --seed
    # changes colours and sampling, never the strands
    strands = prepare_strands(load_strands(args.strands), args.resample, args.densify, seed=0)
    ds = render_dataset(strands, args.output, views=args.views, res=args.res, engine=args.engine,
                        preset=args.preset, seed=args.seed, samples=args.samples, thickness=args.thickness,
                        progress=not args.no_progress, device=args.device, multitone=args.multitone,
                        denoise=args.denoise, backend=args.backend)
    print(f"wrote {len(ds.train)} train + {len(ds.val)} val + {len(ds.test)} test views ({args.res} x {args.res}, "
          f"engine {args.engine}, {strands.count} strands) to {args.output}")
    return 0
