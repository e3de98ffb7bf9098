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


def _predictor(n_points=16, stride=8, counts=None, step=0.01):
    import numpy as np

    counts = np.full(3, n_points) if counts is None else np.asarray(counts)
    return losses.CoderPredictor(n_points, stride, counts, step)


def test_coder_predictor_misses_nothing_on_a_smooth_strand():
    """The coder interpolates with Lagrange polynomials through up to 4 neighbours (3 near a strand's
    end): a quadratic strand is predicted exactly, so a smooth bend costs nothing while point-to-point
    noise does."""
    t = torch.linspace(0, 1, 16, dtype=torch.float64)[:, None]
    bent = torch.cat([t, t ** 2 - 0.5 * t, 2 * t ** 2 - t], 1)[None].repeat(3, 1, 1)
    pred = _predictor()
    assert pred.residuals(bent).abs().max() < 1e-12
    assert float(losses.geometry_rate(bent, pred)) < 1e-10
    noisy = bent + 0.01 * torch.randn(bent.shape, generator=torch.Generator().manual_seed(0), dtype=bent.dtype)
    assert float(losses.geometry_rate(noisy, pred)) > 0.3  # bits a coordinate at noise of one step


def test_geometry_rate_gradient_matches_finite_differences():
    points = torch.randn(3, 16, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(1), requires_grad=True)
    pred = _predictor(step=0.3)
    assert torch.autograd.gradcheck(lambda p: losses.geometry_rate(p, pred), (points,), eps=1e-6, atol=1e-6)
    # pulling the points along minus the gradient makes them cheaper to code
    rate = losses.geometry_rate(points, pred)
    (grad,) = torch.autograd.grad(rate, points)
    assert float(losses.geometry_rate(points.detach() - 0.05 * grad / grad.norm(), pred)) < rate.item()


def test_geometry_rate_counts_each_strands_own_points_only():
    """Samples past a strand's own count (placeholders, spec 3), or predicted from one, add nothing."""
    points = torch.zeros(2, 16, 3, dtype=torch.float64)
    points[1, 12:] = 5.0  # junk beyond strand 1's 12 points
    pred = _predictor(counts=[16, 12])
    assert float(losses.geometry_rate(points, pred)) == 0.0
    assert float(losses.geometry_rate(points, _predictor(counts=[16, 16]))) > 0
