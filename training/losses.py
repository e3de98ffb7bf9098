"""Losses and metrics: L1, SSIM / D-SSIM, alpha loss, opacity smoothness, PSNR, and the strand coder's rate."""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_C1 = 0.01 ** 2
SSIM_C2 = 0.03 ** 2


def _gaussian_taps(dtype: torch.dtype, device: torch.device) -> Tensor:
    x = torch.arange(SSIM_WINDOW, dtype=dtype, device=device) - SSIM_WINDOW // 2
    g = torch.exp(-(x * x) / (2 * SSIM_SIGMA ** 2))
    return g / g.sum()


def ssim(a: Tensor, b: Tensor) -> Tensor:
    """Mean SSIM of two images ``[H, W, 3]`` in [0, 1] (11x11 Gaussian window, sigma 1.5, as 3DGS).

    The window is separable: one 11-tap pass along each axis, all five local moments at once.
    """
    x = a.permute(2, 0, 1)
    y = b.permute(2, 0, 1)
    maps = torch.cat([x, y, x * x, y * y, x * y])[None]  # [1, 15, H, W]
    taps = _gaussian_taps(a.dtype, a.device)
    pad = SSIM_WINDOW // 2
    n = maps.shape[1]
    blurred = F.conv2d(maps, taps.reshape(1, 1, -1, 1).expand(n, 1, -1, 1), padding=(pad, 0), groups=n)
    blurred = F.conv2d(blurred, taps.reshape(1, 1, 1, -1).expand(n, 1, 1, -1), padding=(0, pad), groups=n)
    mx, my, exx, eyy, exy = blurred[0].split(3)
    sxx = exx - mx * mx
    syy = eyy - my * my
    sxy = exy - mx * my
    num = (2 * mx * my + SSIM_C1) * (2 * sxy + SSIM_C2)
    den = (mx * mx + my * my + SSIM_C1) * (sxx + syy + SSIM_C2)
    return (num / den).mean()


def l1(a: Tensor, b: Tensor) -> Tensor:
    return (a - b).abs().mean()


def psnr(a: Tensor, b: Tensor) -> float:
    mse = float(((a.detach() - b.detach()) ** 2).mean())
    return float("inf") if mse == 0 else -10.0 * math.log10(mse)


def opacity_smoothness(opacity: Tensor, real: Tensor | None = None) -> Tensor:
    """Mean absolute change of opacity between neighbouring segments of a strand ``[S, P-1]``; with
    ``real`` (``[S, P-1]`` bool, the strands' own segments), between real neighbours only."""
    change = (opacity[:, 1:] - opacity[:, :-1]).abs()
    if real is None:
        return change.mean()
    both = real[:, 1:]  # (a segment is real where the next one is)
    return (change * both).sum() / both.sum().clamp_min(1)


def image_loss(rgb: Tensor, target: Tensor, lambda_dssim: float) -> Tensor:
    """``(1 - lambda) L1 + lambda (1 - SSIM)``, the 3DGS photometric loss."""
    return (1 - lambda_dssim) * l1(rgb, target) + lambda_dssim * (1 - ssim(rgb, target))


class CoderPredictor:
    """The strand coder's predictor of refinement samples (spec 4.3, :func:`cghair_format.quantize.level_plan`):
    each sample between the base samples is predicted by Lagrange interpolation of the world positions
    of its coarser neighbours, and the writer stores what that misses, quantized. Built once per run
    from the strands' point count, the writer's first base stride and each strand's own count."""

    def __init__(self, n_points: int, base_stride: int, counts: np.ndarray, step: float,
                 device: torch.device | str = "cpu"):
        from cghair_format.quantize import level_plan

        _, levels = level_plan(n_points, base_stride)
        idx = np.concatenate([np.zeros(0, np.int64)] + [lv[0] for lv in levels])
        nb = np.concatenate([np.zeros((0, 4), np.int64)] + [lv[1] for lv in levels])
        wt = np.concatenate([np.zeros((0, 4))] + [lv[2] for lv in levels])
        # a row counts for a strand when the sample and every neighbour it is predicted from are its own points
        last = np.maximum(idx, np.where(wt != 0, nb, 0).max(1))
        self.idx = torch.as_tensor(idx, device=device)  # [R]
        self.nb = torch.as_tensor(nb, device=device)  # [R, 4]
        self.wt = torch.as_tensor(wt, device=device)  # [R, 4] float64, cast to the points' dtype
        self.keep = torch.as_tensor(last[None, :] < np.asarray(counts)[:, None], device=device)  # [S, R] bool
        self.step = float(step)  # the writer's position step, world units

    def residuals(self, points: Tensor) -> Tensor:
        """What the predictor misses ``[S, R, 3]`` on strands ``points [S, P, 3]`` (world)."""
        pred = (points[:, self.nb] * self.wt.to(points.dtype)[None, :, :, None]).sum(2)
        return points[:, self.idx] - pred


def geometry_rate(points: Tensor, predictor: CoderPredictor) -> Tensor:
    """Estimated bits per stored coordinate of strands ``points [S, P, 3]``: the mean over the coder's
    refinement samples (:class:`CoderPredictor`) of ``log2(1 + |residual| / step)``, a smooth stand-in
    for the bits an entropy coder spends on a residual of ``|residual| / step`` steps. Smooth strands
    (curls included: the cubic predictor follows them) cost about nothing; the point-to-point roughness
    that geometry training adds costs a few bits a coordinate, which this term pulls back."""
    r = predictor.residuals(points).abs() / predictor.step
    bits = torch.log2(1 + r).sum(-1)  # [S, R]
    keep = predictor.keep
    return (bits * keep).sum() / (3 * keep.sum().clamp_min(1))
