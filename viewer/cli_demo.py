"""``cgh demo -o DIR``: the main job end to end on built-in data, in a few minutes on a laptop CPU.

Synthesise a hairstyle, render a small multi-view dataset, build cards, train the compact model
briefly, write the .cgh, evaluate it on held-out views, compare its size with the same Gaussians as
a 3DGS PLY, export USD, and render a picture with the viewer.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from training.cli_train import add_backend_argument


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", default="demo_out", help="folder for everything the demo writes")
    p.add_argument("--style", default="wavy", help="built-in hairstyle (see cgh synth)")
    p.add_argument("--strands", type=int, default=2000, help="strand count (default 2000)")
    p.add_argument("--iters", type=int, default=300, help="training iterations (default 300)")
    p.add_argument("--views", type=int, default=24, help="dataset views (default 24)")
    p.add_argument("--res", type=int, default=128, help="dataset resolution (default 128)")
    add_backend_argument(p)


def _step(title: str) -> float:
    print(f"\n== {title}", flush=True)
    return time.perf_counter()


def run(args: argparse.Namespace) -> int:
    from cghair_format import CghError, read_info, read_with_gaussians
    from cghair_format.cli.info import format_info
    from cghair_format.exchange import export_usd, save_strands, write_3dgs_ply
    from cghair_format.synth import synthesize

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    t = _step(f"1. synthesise a '{args.style}' hairstyle ({args.strands} strands x 32 points, two-tone)")
    strands = synthesize(args.style, args.strands, 32, seed=0, multitone=True)
    save_strands(strands, out / "strands.npz")
    print(f"   wrote {out / 'strands.npz'} ({time.perf_counter() - t:.1f} s)")

    from training.config import TrainConfig
    from training.datasets.synthetic import render_dataset
    from training.evaluate import evaluate
    from training.train import train

    t = _step(f"2. render a dataset: {args.views} views at {args.res} x {args.res} (reference splatter)")
    render_dataset(strands, out / "dataset", views=args.views, res=args.res, engine="splat")
    print(f"   wrote {out / 'dataset'} ({time.perf_counter() - t:.1f} s)")

    t = _step(f"3. build cards and train the compact model ({args.iters} iterations)")
    config = TrainConfig(iterations=args.iters, n_cards=64, n_groups=8, points_per_strand=32, card_segments=16,
                         geometry_frozen_iters=args.iters // 2, checkpoint_every=max(args.iters, 1),
                         log_every=max(args.iters // 6, 1))
    result = train(out / "dataset", strands=strands, out=out / "hair.cgh", config=config, backend=args.backend)
    print(f"   wrote {out / 'hair.cgh'} ({time.perf_counter() - t:.1f} s, {result.backend} rasterizer)")

    t = _step("4. the file (cgh info) and the same Gaussians as a 3DGS PLY")
    info = read_info(out / "hair.cgh")
    print(format_info(str(out / "hair.cgh"), info))
    asset, gaussians = read_with_gaussians(out / "hair.cgh")
    write_3dgs_ply(gaussians, out / "hair_3dgs.ply", source_up=asset.up_axis, meters_per_unit=asset.meters_per_unit)
    ply = (out / "hair_3dgs.ply").stat().st_size
    print(f"   3DGS PLY of the same {info['gaussians']:,} Gaussians: {ply:,} bytes; "
          f".cgh: {info['file_bytes']:,} bytes ({ply / info['file_bytes']:.0f} x smaller)")

    t = _step("5. evaluate on the held-out views")
    scores = evaluate(out / "hair.cgh", out / "dataset", out_dir=out / "eval", backend=args.backend)
    print(f"   {scores.summary()}")
    print(f"   side-by-side images in {out / 'eval'} ({time.perf_counter() - t:.1f} s)")

    t = _step("6. export USD (curves with groom primvars, and the cards)")
    export_usd(out / "hair.usda", asset=asset, curves=True, cards=True)
    print(f"   wrote {out / 'hair.usda'}")

    t = _step("7. render a picture with the viewer (headless EGL)")
    from .render_jobs import RenderJob, render_job

    try:
        path = render_job(asset, RenderJob(width=512, height=512, azimuth=30, elevation=10), out / "hair.png")
        print(f"   wrote {path} ({time.perf_counter() - t:.1f} s)")
    except CghError as exc:  # no OpenGL 4.3 here: the rest of the demo stands
        print(f"   no picture: {exc}")
    print(f"\ndemo finished in {time.perf_counter() - start:.0f} s; everything is in {out}/")
    return 0
