"""``cgh reconstruct DATASET -o strands.usdc [--scalp MESH] [--strands N] [--debug-dir D]
[--backend B] [--resume CKPT]``: multi-view images with masks and cameras -> strands.

Stages (see :mod:`training.reconstruct.pipeline`): 2D orientation maps, visual hull and 3D
orientation field, scalp roots, growth, refinement through the splatter. Writes the strands, the
checkpoint ``<out>.recon.npz`` (``--resume`` continues from it) and ``<out>.recon.json``
(config, stage timings, loss history).
"""

from __future__ import annotations

import argparse

from cghair_format.cli.argtypes import int_at_least, non_negative_float, positive_float
from cghair_format.smooth import RECONSTRUCT_SMOOTH_MM

from .cli_train import add_backend_argument


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", metavar="DATASET", help="dataset folder with hair masks: NeRF-synthetic (RGBA), COLMAP "
                   "or GaussianHaircut layout")
    p.add_argument("-o", "--output", required=True, help="output strand file (.usdc .usda .npz .ply .hair .data .tfx)")
    p.add_argument("--scalp", metavar="MESH", help="scalp mesh to grow from (OBJ, PLY, ... read by trimesh); "
                   "default: a cap estimated from the hair volume")
    p.add_argument("--strands", type=int_at_least(1), default=500, help="strands to grow (default: 500)")
    p.add_argument("--points", type=int_at_least(4), default=32, help="points per strand (default: 32)")
    p.add_argument("--hull-resolution", type=int_at_least(8), default=96,
                   help="voxels along the hair volume's longest side (default: 96)")
    p.add_argument("--refine-iters", type=int_at_least(0), default=100,
                   help="refinement iterations through the splatter (default: 100; 0 skips it)")
    p.add_argument("--meters-per-unit", type=positive_float, default=1.0,
                   help="scale of the dataset's scene units, written into the strands (default: 1)")
    p.add_argument("--prior", metavar="FILE", help="strand prior for the refinement (from cgh fit-strand-prior); "
                   "'none' for no prior (default: the built-in basis of the synthetic styles)")
    p.add_argument("--smooth", type=non_negative_float, metavar="MM", default=RECONSTRUCT_SMOOTH_MM,
                   help="last, low-pass the strands along their length with a Gaussian of MM millimetres, root and "
                        "length kept (default: %(default)s; 0: none; cgh convert --smooth does it to a strand file)")
    p.add_argument("--debug-dir", help="folder for each stage's images (orientation maps, hull projections)")
    p.add_argument("--resume", metavar="CKPT", help="continue from a checkpoint (<out>.recon.npz)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--threads", type=int_at_least(1), default=None, help="torch CPU threads")
    add_backend_argument(p)


def run(args: argparse.Namespace) -> int:
    import json
    from dataclasses import asdict
    from pathlib import Path

    from cghair_format.exchange import UnsupportedFormatError, save_strands, writable_extensions

    from .datasets.layouts import detect_layout
    from .datasets.read import read_dataset
    from .reconstruct.pipeline import ReconstructConfig, reconstruct

    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    out = Path(args.output)
    if out.suffix.lower() not in writable_extensions():  # fail now, not after the long work
        raise UnsupportedFormatError(f"{out}: cannot write strands as {out.suffix or 'a file without extension'}; "
                                     f"known extensions: {', '.join(writable_extensions())}")
    if not out.parent.exists():
        raise FileNotFoundError(2, "No such file or directory", str(out.parent))
    cfg = ReconstructConfig(strands=args.strands, points_per_strand=args.points, hull_resolution=args.hull_resolution,
                            refine_iters=args.refine_iters, meters_per_unit=args.meters_per_unit, seed=args.seed,
                            backend=args.backend, prior=args.prior,
                            smooth_mm=args.smooth)
    ckpt = Path(args.resume) if args.resume else out.with_suffix(".recon.npz")
    ds = read_dataset(args.dataset)
    print(f"read {args.dataset}: {detect_layout(args.dataset).describe()}, {len(ds.train)} training views")
    result = reconstruct(ds, cfg, ckpt, scalp=args.scalp, debug_dir=args.debug_dir, resume=bool(args.resume),
                         log=lambda line: print(line, flush=True))
    save_strands(result.strands, out)
    report = {"config": asdict(cfg), "timings_s": result.timings, "losses": result.losses,
              "strands": result.strands.count}
    out.with_suffix(".recon.json").write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {out} ({result.strands.count} strands), checkpoint {ckpt}")
    return 0
