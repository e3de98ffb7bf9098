"""Losses and metrics against direct formulas."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from training import losses


def _ssim_reference(a, b):
    """Full 11x11 window SSIM written out (the 3DGS formula), float64."""
    x = torch.arange(11, dtype=torch.float64) - 5
    g = torch.exp(-x * x / (2 * 1.5 ** 2))
    g = g / g.sum()
    w = (g[:, None] * g[None]).expand(3, 1, 11, 11)
    xa, xb = a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]

    def blur(t):
        return F.conv2d(t, w, padding=5, groups=3)

    ma, mb = blur(xa), blur(xb)
    saa, sbb, sab = blur(xa * xa) - ma ** 2, blur(xb * xb) - mb ** 2, blur(xa * xb) - ma * mb
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return (((2 * ma * mb + c1) * (2 * sab + c2)) / ((ma ** 2 + mb ** 2 + c1) * (saa + sbb + c2))).mean()


def test_ssim_matches_the_full_window_formula():
    gen = torch.Generator().manual_seed(0)
    a = torch.rand(20, 17, 3, generator=gen, dtype=torch.float64)
    b = (a + 0.1 * torch.randn(20, 17, 3, generator=gen, dtype=torch.float64)).clamp(0, 1)
    assert abs(float(losses.ssim(a, b)) - float(_ssim_reference(a, b))) < 1e-12
    assert abs(float(losses.ssim(a, a)) - 1.0) < 1e-12


def test_psnr_l1_and_smoothness():
    a = torch.zeros(4, 4, 3)
    b = torch.full((4, 4, 3), 0.1)
    assert math.isclose(losses.psnr(a, b), 20.0, rel_tol=1e-5)
    assert losses.psnr(a, a) == float("inf")
    assert math.isclose(float(losses.l1(a, b)), 0.1, rel_tol=1e-6)
    o = torch.tensor([[0.0, 0.5, 0.5, 1.0]])
    assert math.isclose(float(losses.opacity_smoothness(o)), 1.0 / 3, rel_tol=1e-6)
