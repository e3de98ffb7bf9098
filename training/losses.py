"""Image losses and metrics: L1, SSIM / D-SSIM, alpha loss, opacity smoothness, PSNR."""

from __future__ import annotations

import math

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
