"""The compiled card-bound Gaussians (training/_geometry.pyx) against their torch definition
(CardGeometry.points then segment_gaussians), values and gradients, edge cases included."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from cghair_format.examples import example_asset
from training import native_geometry
from training.config import TrainConfig
from training.model import CardGeometry, HairModel, segment_gaussians

pytestmark = pytest.mark.skipif(not native_geometry.available(),
                                reason="training/_geometry is not built: run `make venv`")

# The kernel computes in double from the same float32 inputs and rounds its outputs to float32
# (half an ulp, 6e-8 relative); against torch in float64 on the same inputs a value may differ
# by a few ulps of coordinates of order 1, and a gradient by that relative amount plus the
# rounding of its terms: 1e-6 leaves room for both and still catches any wrong term.
VALUE_TOL = 4e-6
GRAD_REL_TOL = 1e-6


def _reference(geometry, uv: torch.Tensor, delta: torch.Tensor, thickness: float):
    """The torch definition, in float64 (the same float32 inputs, widened)."""
    ns = SimpleNamespace(segments=geometry.segments, vertex_data=geometry.vertex_data.double(),
                         triangles=geometry.triangles, strand_card=geometry.strand_card)
    return segment_gaussians(CardGeometry.points(ns, uv.double(), delta.double()), thickness)


def _compare(geometry, uv: np.ndarray, delta: np.ndarray, thickness: float, seed: int = 0) -> None:
    uv32 = torch.tensor(uv, dtype=torch.float32, requires_grad=True)
    d32 = torch.tensor(delta, dtype=torch.float32, requires_grad=True)
    uv64 = uv32.detach().double().requires_grad_(True)
    d64 = d32.detach().double().requires_grad_(True)
    ours = native_geometry.segment_gaussians(geometry, uv32, d32, thickness)
    ref = _reference(geometry, uv64, d64, thickness)
    for a, b in zip(ours, ref, strict=True):
        assert a.dtype == torch.float32
        assert np.abs(a.detach().double().numpy() - b.detach().numpy()).max() <= VALUE_TOL
    gen = torch.Generator().manual_seed(seed)
    weights = [torch.randn(t.shape, generator=gen, dtype=torch.float64) for t in ref]
    sum(((a.double() * w).sum() for a, w in zip(ours, weights, strict=True))).backward()
    sum(((b * w).sum() for b, w in zip(ref, weights, strict=True))).backward()
    for mine, truth in ((uv32.grad, uv64.grad), (d32.grad, d64.grad)):
        err = float((mine.double() - truth).norm() / truth.norm())
        assert err <= GRAD_REL_TOL, err


def test_matches_torch_on_a_card_built_asset_with_points_off_the_strip():
    asset = example_asset(seed=1, sh_degree=1)
    model = HairModel(asset, TrainConfig(codebook_size=4, latent_dim=8, mlp_hidden=[16], sh_degree=1))
    rng = np.random.default_rng(0)
    uv = model.uv.detach().numpy() + 1e-3 * rng.normal(size=model.uv.shape)
    delta = model.delta.detach().numpy() + 1e-3 * rng.normal(size=model.delta.shape)
    uv[0, 0] = (-0.1, 0.5)  # before the strip's first segment
    uv[0, 1] = (1.2, 0.4)  # past its last
    uv[1, 2] = (0.3, 1.3)  # beside it, either side
    uv[1, 3] = (0.3, -0.2)
    uv[2, 4], delta[2, 4] = uv[2, 3], delta[2, 3]  # a zero-length segment
    _compare(model.geometry, uv, delta, asset.thickness)


def test_matches_torch_on_segments_along_minus_z_and_of_zero_length():
    """One flat card with normal +z: points stacked by delta give segments along -z (the fixed
    quaternion), equal ones zero-length segments, and the rest slant."""
    vertices = np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0]], np.float32)  # L0, R0, L1, R1
    normals = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
    geometry = SimpleNamespace(segments=1, vertex_data=torch.as_tensor(np.hstack([vertices, normals])),
                               triangles=torch.tensor([[0, 1, 2], [1, 3, 2]]), strand_card=torch.tensor([0, 0]))
    uv = np.array([[[0.3, 0.3]] * 4, [[0.1, 0.2], [0.4, 0.5], [0.9, 0.7], [0.9, 0.7]]], np.float32)
    delta = np.array([[0.5, 0.2, 0.2, -0.1], [0.0, 0.1, 0.3, 0.3]], np.float32)
    _, quats, scales = native_geometry.segment_gaussians(geometry, torch.as_tensor(uv), torch.as_tensor(delta), 0.01)
    assert torch.equal(quats[0], torch.tensor([0.0, 1.0, 0.0, 0.0])) and scales[1, 2] == 0
    _compare(geometry, uv, delta, 0.01)


def test_the_model_uses_the_kernel_and_agrees_with_its_torch_path(monkeypatch):
    asset = example_asset(seed=2, sh_degree=1)
    model = HairModel(asset, TrainConfig(codebook_size=4, latent_dim=8, mlp_hidden=[16], sh_degree=1))
    calls, kernel_path = [], native_geometry.segment_gaussians
    monkeypatch.setattr(native_geometry, "segment_gaussians", lambda *a: calls.append(1) or kernel_path(*a))
    native = model.gaussian_geometry()
    assert calls
    monkeypatch.setattr(native_geometry, "_geometry", None)
    torch_path = model.gaussian_geometry()
    for a, b in zip(native, torch_path, strict=True):
        assert np.abs(a.detach().numpy() - b.detach().numpy()).max() <= VALUE_TOL
