"""How much each quantization costs in the picture: render PSNR against the unquantized asset.

    python -m training.precision MODEL.cgh DATASET_DIR [--split val] [--weight-steps 0.02,0.35,0.5]
                                 [--mlp-steps 0.7,1] [--logit-levels 1023,63]

``MODEL.cgh`` is the reference (write it with ``--profile lossless`` to measure every profile);
the cameras come from the dataset's split (default ``val``: the validation views, since these
figures choose settings; see :meth:`training.datasets.types.Dataset.split`). For each profile the
file is encoded, decoded and rendered; for each weight step (a fraction of each array's RMS, as the
profiles give it) only the codebooks and MLP weights are quantized, for each MLP step only the MLP's
(the compact profile gives it its own), and for each logit level count
only the soft logits, each as the writer stores them, which isolates each one's share of the error.
"""

from __future__ import annotations

import argparse
import copy
import sys

import numpy as np
import torch

from cghair_format import decode, decode_gaussians, encode, read
from cghair_format.asset import HairAsset
from cghair_format.quantize import (
    softmax_levels_decode,
    softmax_levels_encode,
    weight_steps,
    weights_decode,
    weights_encode,
)

from .datasets.read import read_dataset
from .datasets.types import SPLITS, View
from .losses import psnr
from .splatter import render_gaussians


def render_views(asset: HairAsset, views: list[View]) -> torch.Tensor:
    g = decode_gaussians(asset)
    return torch.as_tensor(np.stack([render_gaussians(g, v.camera)["rgb"] for v in views]), dtype=torch.float64)


def with_weight_step(asset: HairAsset, fraction: float | None, mlp_fraction: float | None = None) -> HairAsset:
    """A copy with codebooks (None: exact) and MLP weights and biases on steps of ``fraction`` (the MLP's
    ``mlp_fraction``, default ``fraction``) of each array's RMS, as the writer stores them, everything
    else exact."""
    out = copy.deepcopy(asset)
    app = out.appearance
    layers = [(layer.weight, layer.bias) for layer in app.mlp]
    steps = weight_steps(app.codebooks, layers, fraction or 1.0, mlp_fraction or fraction)
    codebooks, decoded = weights_decode(steps, *weights_encode(steps, app.codebooks, layers))
    app.codebooks = app.codebooks if fraction is None else codebooks
    for layer, (w, b) in zip(app.mlp, decoded, strict=True):
        layer.weight, layer.bias = w, b
    return out


def with_logit_levels(asset: HairAsset, levels: int, floor: float = -16.0) -> HairAsset:
    """A copy with soft logits stored on ``levels`` softmax levels, everything else exact."""
    out = copy.deepcopy(asset)
    app = out.appearance
    if app.weight_mode == "soft":
        q = softmax_levels_encode(app.logits, app.temperature, levels)
        app.logits = softmax_levels_decode(q, app.temperature, levels, floor).astype(np.float32)
    return out


def measure(asset: HairAsset, views: list[View], profiles=("high", "compact"), steps=(0.02, 0.35, 0.5),
            logit_levels=(1023, 63), mlp_steps=()) -> list[dict]:
    reference = render_views(asset, views)
    rows = []
    for profile in profiles:
        data, _ = encode(asset, profile)
        rows.append({"what": f"{profile} file", "bytes": len(data),
                     "psnr": psnr(render_views(decode(data), views), reference)})
    for f in steps:
        rows.append({"what": f"weight step {f:g} only", "bytes": None,
                     "psnr": psnr(render_views(with_weight_step(asset, f), views), reference)})
    for f in mlp_steps:
        rows.append({"what": f"MLP step {f:g} only", "bytes": None,
                     "psnr": psnr(render_views(with_weight_step(asset, None, f), views), reference)})
    for n in logit_levels if asset.appearance.weight_mode == "soft" else ():
        rows.append({"what": f"{n} logit levels only", "bytes": None,
                     "psnr": psnr(render_views(with_logit_levels(asset, n), views), reference)})
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.precision", description=__doc__.split("\n\n")[0])
    p.add_argument("cgh", help="the reference asset (.cgh, ideally lossless)")
    p.add_argument("dataset", help="a NeRF-synthetic dataset folder, for its cameras")
    p.add_argument("--split", default="val", choices=SPLITS,
                   help="views whose cameras are used (default: val, the views for choosing settings)")
    p.add_argument("--weight-steps", default="0.02,0.35,0.5",
                   help="weight steps to try, as fractions of each array's RMS (0 < step <= 4)")
    p.add_argument("--mlp-steps", default="",
                   help="steps of the MLP's weights alone to try, as fractions of each layer's RMS (0 < step <= 4)")
    p.add_argument("--logit-levels", default="1023,63", help="soft-logit level counts to try (1..65535)")
    args = p.parse_args(argv)
    try:
        steps = tuple(float(f) for f in args.weight_steps.split(","))
        mlp_steps = tuple(float(f) for f in args.mlp_steps.split(",") if f)
        levels = tuple(int(n) for n in args.logit_levels.split(","))
    except ValueError:
        p.error(f"--weight-steps and --mlp-steps take comma-separated numbers and --logit-levels integers, got "
                f"{args.weight_steps!r}, {args.mlp_steps!r}, {args.logit_levels!r}")
    if not all(0 < f <= 4 for f in steps + mlp_steps):
        p.error("--weight-steps and --mlp-steps must lie in (0, 4]")
    if not all(1 <= n <= 65535 for n in levels):
        p.error("--logit-levels must lie in 1..65535")
    from cghair_format.errors import CghError

    try:
        asset, views = read(args.cgh), read_dataset(args.dataset).split(args.split)
    except (CghError, OSError) as exc:
        print(f"python -m training.precision: error: {exc}", file=sys.stderr)
        return 1
    print(f"render PSNR against {args.cgh} on {len(views)} {args.split} views")
    for row in measure(asset, views, steps=steps, logit_levels=levels, mlp_steps=mlp_steps):
        size = f"{row['bytes']:>10,} B" if row["bytes"] is not None else " " * 12
        print(f"{row['what']:<22} {size}  {row['psnr']:7.2f} dB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
