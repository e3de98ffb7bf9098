"""Which Gaussians the pictures hardly use: each one's blend weight summed over a set of views.

A Gaussian's blend weight at a pixel is ``T * alpha``, its share of the pixel's colour
(spec/rendering.md). Summed over the training views it says how much of the pictures rests on it.
In trained hair most Gaussians sit inside the volume or behind others: on the paper-scale model 93 %
of them carry 10 % of the training views' weight (docs/ablation.md, "Negligible opacities").

Lowering a Gaussian's opacity changes a pixel by at most twice its weight there (it gives up part
of its own colour, and what lies behind it can show by no more than that), and never makes anything
appear. So the Gaussians that together carry a small share (``budget``) of all the weight may be
stored at a lower opacity, down to 0: :func:`cghair_format.encode`'s ``negligible``, which codes
them for almost nothing.
"""

from __future__ import annotations

import numpy as np
import torch

from cghair_format.asset import HairAsset
from cghair_format.gaussians import SH_C0, gaussian_frames

from .backends import render, resolve_backend
from .datasets.types import View
from .splatter import torch_device


def blend_weights(means: np.ndarray, rotations: np.ndarray, scales: np.ndarray, opacities: np.ndarray,
                  views: list[View], backend: str | None = None, device: str | torch.device = "cpu") -> np.ndarray:
    """Each Gaussian's blend weight summed over every pixel of every view ``[G]`` (float64), from one
    backward pass a view: with all SH zero every colour is 0.5, and the red channel's derivative with
    respect to a Gaussian's first SH coefficient is ``SH_C0`` times its blend weight."""
    device = torch_device(device)
    backend = resolve_backend(backend, device)
    geometry = [torch.as_tensor(np.ascontiguousarray(a, np.float32), device=device)
                for a in (means, rotations, scales, opacities)]
    total = torch.zeros(len(opacities), dtype=torch.float64, device=device)
    for view in views:
        sh = torch.zeros(len(opacities), 1, 3, device=device, requires_grad=True)
        render(backend, *geometry, sh, view.camera).rgb[..., 0].sum().backward()
        total += sh.grad[:, 0, 0].double() / SH_C0
    return total.cpu().numpy()


def least_weight(weights: np.ndarray, budget: float) -> np.ndarray:
    """The Gaussians (bool ``[G]``) that, lightest first, together carry at most ``budget`` (a share
    in [0, 1)) of the summed weight."""
    if not 0 <= budget < 1:
        raise ValueError(f"the opacity budget is a share of the blend weight in [0, 1), got {budget}")
    chosen = np.zeros(len(weights), bool)
    order = np.argsort(weights, kind="stable")
    carried = np.cumsum(weights[order])
    if len(carried) and carried[-1] > 0:  # (views that see none of them say nothing)
        chosen[order[carried <= budget * carried[-1]]] = True
    return chosen


def negligible_segments(asset: HairAsset, views: list[View], budget: float, backend: str | None = None,
                        device: str | torch.device = "cpu") -> np.ndarray:
    """The segments (bool ``[S, P-1]``, like ``asset.opacity``) whose Gaussians together carry at most
    ``budget`` of the blend weight over ``views``: what :func:`cghair_format.encode` may store lower.
    Placeholder segments (variable point counts) are not marked."""
    weights = blend_weights(*gaussian_frames(asset), views, backend, device)
    marked = np.zeros(asset.opacity.shape, bool)
    marked[asset.real_segments()] = least_weight(weights, budget)
    return marked
