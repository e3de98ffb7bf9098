"""The compiled card-bound Gaussians: :meth:`training.model.CardGeometry.points` followed by
:func:`training.model.segment_gaussians` in one pass per strand, forward and backward
(:mod:`training._geometry`), instead of some thirty full-size torch operations each way.

Used by :meth:`training.model.HairModel.gaussian_geometry` for float32 CPU tensors when the kernel
is built; the torch functions are the definition and run everywhere else
(tests/training/test_native_geometry.py holds the two together).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

try:
    from training import _geometry
except ImportError:  # not built: the model uses the torch functions
    _geometry = None


def available() -> bool:
    return _geometry is not None


def usable(*tensors: Tensor) -> bool:
    """Whether the kernel can take these tensors: built, CPU, float32."""
    return available() and all(t.device.type == "cpu" and t.dtype == torch.float32 for t in tensors)


def _np(t: Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().numpy())


class _SegmentGaussians(torch.autograd.Function):
    @staticmethod
    def forward(ctx, uv, delta, geometry, thickness):
        s, p = delta.shape
        g = s * max(p - 1, 0)
        means, quats, scales = np.empty((g, 3), np.float32), np.empty((g, 4), np.float32), np.empty((g, 3), np.float32)
        arrays = (_np(uv), _np(delta), _np(geometry.vertex_data), _np(geometry.triangles), _np(geometry.strand_card))
        _geometry.forward(*arrays, geometry.segments, thickness, means, quats, scales)
        ctx.arrays, ctx.segments = arrays, geometry.segments
        return torch.from_numpy(means), torch.from_numpy(quats), torch.from_numpy(scales)

    @staticmethod
    def backward(ctx, grad_means, grad_quats, grad_scales):
        uv, delta = ctx.arrays[:2]
        g = delta.shape[0] * max(delta.shape[1] - 1, 0)
        zero = {3: np.zeros((g, 3), np.float32), 4: np.zeros((g, 4), np.float32)}
        grads = [_np(t.float()) if t is not None else zero[n] for t, n in ((grad_means, 3), (grad_quats, 4),
                                                                         (grad_scales, 3))]
        grad_uv, grad_delta = np.empty_like(uv), np.empty_like(delta)
        _geometry.backward(*ctx.arrays, ctx.segments, *grads, grad_uv, grad_delta)
        ctx.arrays = None
        return torch.from_numpy(grad_uv), torch.from_numpy(grad_delta), None, None


def segment_gaussians(geometry, uv: Tensor, delta: Tensor, thickness: float) -> tuple[Tensor, Tensor, Tensor]:
    """Means, quaternions (w, x, y, z) and scales ``[S*(P-1), ...]`` of the strands at card coordinates
    ``uv [S, P, 2]``, ``delta [S, P]`` on ``geometry`` (a :class:`training.model.CardGeometry`)."""
    return _SegmentGaussians.apply(uv, delta, geometry, float(thickness))
