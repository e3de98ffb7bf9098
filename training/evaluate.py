"""Evaluation on held-out views: PSNR, SSIM, LPIPS (:mod:`training.lpips`, AlexNet by default), and
full-size side-by-side images (ground truth | render | 4 x absolute difference) per view."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from cghair_format.asset import HairAsset
from cghair_format.atomic import atomic_path, write_text

from . import losses
from .datasets.read import read_dataset
from .datasets.types import Dataset, View

DIFF_GAIN = 4.0


@dataclass
class EvalResult:
    psnr: float  # mean over views
    ssim: float
    lpips: float | None
    lpips_note: str  # why LPIPS is missing, or which network
    per_view: list[dict] = field(default_factory=list)
    images: list[Path] = field(default_factory=list)
    split: str = ""  # the dataset's views scored: test (reported), val (choosing settings) or train

    def summary(self) -> str:
        lp = f"{self.lpips:.4f} ({self.lpips_note})" if self.lpips is not None else f"skipped ({self.lpips_note})"
        return (f"{len(self.per_view)} views: PSNR {self.psnr:.2f} dB, SSIM {self.ssim:.4f}, LPIPS {lp}")

    def to_dict(self) -> dict:
        return {"split": self.split, "psnr": self.psnr, "ssim": self.ssim, "lpips": self.lpips,
                "lpips_note": self.lpips_note, "per_view": self.per_view, "images": [str(p) for p in self.images]}


def _lpips_model(net: str, size: int) -> tuple[Callable | None, str]:
    """Our LPIPS network (:mod:`training.lpips`), or None and why when the images are too small
    for it. Missing weights raise :class:`training.lpips.LpipsWeightsError`, saying how to get them."""
    from .lpips import Lpips

    model = Lpips(net)
    if size < model.min_size:
        return None, f"{net} needs views of at least {model.min_size} px, these have {size}"
    return model, net


def _side_by_side(gt: np.ndarray, pred: np.ndarray) -> np.ndarray:
    diff = np.clip(np.abs(gt - pred) * DIFF_GAIN, 0, 1)
    return (np.concatenate([gt, np.clip(pred, 0, 1), diff], axis=1) * 255 + 0.5).astype(np.uint8)


def evaluate_renders(render_fn: Callable[[View], np.ndarray], views: list[View], out_dir: str | Path | None = None,
                     background=(0.0, 0.0, 0.0), use_lpips: bool = True, lpips_net: str = "alex") -> EvalResult:
    """Metrics of ``render_fn(view) -> rgb [H, W, 3]`` against each view composited on ``background``;
    LPIPS with the ``lpips_net`` backbone (alex or vgg)."""
    from PIL import Image

    size = min(min(v.image.shape[:2]) for v in views) if views else 0
    net, note = _lpips_model(lpips_net, size) if use_lpips else (None, "disabled")
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    per_view, images = [], []
    for i, view in enumerate(views):
        gt = view.premultiplied(background).astype(np.float32)
        pred = np.asarray(render_fn(view), np.float32)
        a, b = torch.as_tensor(pred), torch.as_tensor(gt)
        rec = {"view": view.name or str(i), "psnr": losses.psnr(a.clamp(0, 1), b),
               "ssim": float(losses.ssim(a.clamp(0, 1), b))}
        if net is not None:
            with torch.no_grad():
                rec["lpips"] = float(net(a.clamp(0, 1).permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]))
        per_view.append(rec)
        if out is not None:
            path = out / f"{view.name or f'view_{i:03d}'}_gt_render_diff.png"
            with atomic_path(path) as tmp:
                Image.fromarray(_side_by_side(gt, pred)).save(tmp)
            images.append(path)
    if not per_view:
        raise ValueError("no views to evaluate")
    mean = {k: float(np.mean([r[k] for r in per_view])) for k in ("psnr", "ssim")}
    lp = float(np.mean([r["lpips"] for r in per_view])) if net is not None else None
    return EvalResult(mean["psnr"], mean["ssim"], lp, note, per_view, images)


def evaluate(cgh: str | Path | HairAsset, dataset: str | Path | Dataset, out_dir: str | Path | None = None,
             split: str = "test", background=(0.0, 0.0, 0.0), use_lpips: bool = True,
             device: str = "cpu", lpips_net: str = "alex", backend: str | None = None) -> EvalResult:
    """Render a .cgh (decoded exactly as stored) at the dataset's ``split`` views on the torch
    ``device`` with ``backend`` (default: the fastest that runs there) and compare. ``split`` is
    ``test`` for the held-out scores to report, ``val`` for choosing settings (a dataset without
    validation views gives its training views, with a warning, and the result's ``split`` says so)."""
    from cghair_format import decode_gaussians, read_with_gaussians

    from .backends import render_gaussians, resolve_backend
    from .splatter import torch_device

    device = torch_device(device)
    backend = resolve_backend(backend, device)
    g = decode_gaussians(cgh) if isinstance(cgh, HairAsset) else read_with_gaussians(cgh)[1]
    ds = dataset if isinstance(dataset, Dataset) else read_dataset(dataset)
    result = evaluate_renders(lambda v: render_gaussians(g, v.camera, tuple(background), device, backend)["rgb"],
                              ds.split(split), out_dir, background, use_lpips, lpips_net)
    result.split = split if split != "val" or ds.val else "train (no val views)"
    if out_dir is not None:
        write_text(Path(out_dir) / "metrics.json", json.dumps(result.to_dict(), indent=2) + "\n")
    return result


def evaluate_model(model, views: list[View], mode: str = "soft", tau: float = 0.1, background=(0.0, 0.0, 0.0),
                   out_dir: str | Path | None = None, use_lpips: bool = False, lpips_net: str = "alex",
                   backend: str = "reference") -> EvalResult:
    """Metrics of a torch :class:`training.model.HairModel` (for variants without a .cgh encoding)."""
    from .backends import renderer

    render = renderer(backend)

    if model.variant in ("unique", "single-sh"):
        mode = "soft"  # no weights involved
    with torch.no_grad():
        gauss = model(mode, tau)

    def fn(view: View) -> np.ndarray:
        with torch.no_grad():
            return render(*gauss, view.camera, tuple(background)).rgb.cpu().numpy()

    return evaluate_renders(fn, views, out_dir, background, use_lpips, lpips_net)
