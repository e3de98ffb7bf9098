"""``cgh render-dataset STRANDS -o DIR --views N --res R --engine cycles|splat``.

Writes a NeRF-synthetic dataset (transforms_train/test.json + RGBA PNGs, alpha = hair mask).
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
                   "8th is held out for testing)")
    p.add_argument("--res", type=int_at_least(8), default=128, help="image width and height (default: 128)")
    p.add_argument("--engine", choices=ENGINES, default="splat",
                   help="splat: our splatter from a known appearance (fast); cycles: Blender Cycles with the "
                        "Principled Hair BSDF (needs bpy, the 'blender' extra)")
    p.add_argument("--preset", choices=PRESETS, default="brown",
                   help="hair colour when the strands carry none (default: brown)")
    p.add_argument("--samples", type=int_at_least(1), default=16, help="Cycles samples per pixel (default: 16)")
    p.add_argument("--thickness", type=positive_float, default=None,
                   help="strand radius in scene units (default: the card builder's rule)")
    p.add_argument("--seed", type=int, default=0, help="seed of the per-strand colour variation (default: 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--device", default="cpu", help="torch device of the splat engine, e.g. cpu or cuda (default: cpu)")
    add_backend_argument(p)


def run(args: argparse.Namespace) -> int:
    from cghair_format.exchange import load_strands

    from .dataset import render_dataset

    strands = load_strands(args.strands)
    ds = render_dataset(strands, args.output, views=args.views, res=args.res, engine=args.engine,
                        preset=args.preset, seed=args.seed, samples=args.samples, thickness=args.thickness,
                        progress=not args.no_progress, device=args.device, backend=args.backend)
    print(f"wrote {len(ds.train)} train + {len(ds.test)} test views ({args.res} x {args.res}, "
          f"engine {args.engine}) to {args.output}")
    return 0
