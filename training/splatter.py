"""The reference 3D Gaussian splatter: pure torch, differentiable, CPU and CUDA.

This is the source of truth for the image model shared with the viewer and the native splatter
(the rendering contract, spec/rendering.md): EWA projection with a 0.3 px^2 dilation,
alpha = min(0.99, o exp(-q/2)) with contributions under 1/255 skipped, a 3-sigma square support,
colour from SH per Gaussian and front-to-back compositing in camera-depth order.

Cost grows with the pixels each Gaussian covers, not with pixels x Gaussians: every Gaussian's
support square is expanded into (pixel, Gaussian) pairs, the pairs are sorted by one key
(pixel, depth rank), and the transmittance of each pair is a segmented exclusive cumulative sum
of ``log(1 - alpha)`` within its pixel's run. Autograd differentiates all of it.

No early termination at T < 1e-4 (allowed by the contract, section 6, with its bound): this
renderer composites every contribution.

Support rule (both renderers): with ``r = ceil(3 sqrt(lambda_max(Sigma2)))``, Gaussian ``g``
touches pixel ``(i, j)`` iff ``|i + 0.5 - m_x| <= r`` and ``|j + 0.5 - m_y| <= r``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

from cghair_format.errors import CghError
from cghair_format.gaussians import sh_polynomial

if TYPE_CHECKING:
    from cghair_format.camera import Camera
    from cghair_format.gaussians import Gaussians


NEAR_PLANE = 0.01  # camera-space z below which a Gaussian is culled
DILATION = 0.3  # px^2 added to the 2D covariance's diagonal (low-pass filter)
ALPHA_MAX = 0.99  # per-contribution alpha clamp
ALPHA_MIN = 1.0 / 255.0  # contributions below this are skipped
SIGMA_SUPPORT = 3.0  # support half-size in standard deviations (largest axis)


class DeviceError(CghError, ValueError):
    """A torch device name this torch cannot use."""


def torch_device(name: str | torch.device) -> torch.device:
    """The torch device ``name`` ("cpu", "cuda", "cuda:1", ...), or a DeviceError that says why not."""
    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError) as exc:
        raise DeviceError(f"unknown torch device {name!r} ({exc})") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise DeviceError(f"device {name!r} asked for, but this torch has no usable CUDA device (install a CUDA "
                          "build of torch: see the README)")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise DeviceError(f"device {name!r} asked for, but this machine has {torch.cuda.device_count()} CUDA "
                          f"device(s)")
    return dev


@dataclass
class RenderOutput:
    rgb: Tensor  # [H, W, 3]
    alpha: Tensor  # [H, W]
    depth: Tensor  # [H, W], expected camera depth sum z_i a_i T_i (not normalised)


@dataclass
class Projection:
    """Per-Gaussian screen-space quantities of the Gaussians in front of the near plane."""

    index: Tensor  # [V] long, indices of the visible Gaussians in the input
    mean2d: Tensor  # [V, 2] projected centres (pixels)
    conic: Tensor  # [V, 3] inverse 2D covariance (a, b, c) of [[a, b], [b, c]]
    depth: Tensor  # [V] camera-space z
    radius: Tensor  # [V] long, support half-size in pixels


def quat_to_rotmat(quats: Tensor) -> Tensor:
    """Rotation matrices ``[G, 3, 3]`` of quaternions ``[G, 4]`` (w, x, y, z), normalised here."""
    q = quats / quats.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(*q.shape[:-1], 3, 3)


def eval_sh(sh: Tensor, dirs: Tensor) -> Tensor:
    """RGB ``[G, 3]`` from SH ``[G, (deg+1)^2, 3]`` and unit directions ``[G, 3]`` (3DGS convention):
    the polynomial of :func:`cghair_format.gaussians.sh_polynomial`, ``+ 0.5``, clamped at 0."""
    return torch.clamp_min(sh_polynomial(sh, dirs) + 0.5, 0.0)


def _camera_tensors(camera: Camera, like: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    kw = {"dtype": like.dtype, "device": like.device}
    w2c = torch.as_tensor(np.asarray(camera.world_to_camera, np.float64), **kw)
    center = torch.as_tensor(np.asarray(camera.center, np.float64), **kw)
    return w2c[:3, :3], w2c[:3, 3], center


def project(means: Tensor, quats: Tensor, scales: Tensor, camera: Camera) -> Projection:
    """EWA projection of the Gaussians in front of the near plane (contract steps 1-3)."""
    rot, trans, _ = _camera_tensors(camera, means)
    t_all = means @ rot.T + trans
    index = torch.nonzero(t_all[:, 2] > NEAR_PLANE).squeeze(1)
    t = t_all[index]
    x, y, z = t.unbind(-1)
    fx, fy = float(camera.fx), float(camera.fy)
    m = quat_to_rotmat(quats[index]) * scales[index][:, None, :]  # R_q S, [V, 3, 3]
    # rows of J W (the Jacobian's zeros written out), then A = J W R_q S and Sigma2 = A A^T + 0.3 I;
    # explicit rows instead of batched 2x3 @ 3x3 products: faster on CPU (docs/ablation.md)
    jw0 = (fx / z)[:, None] * rot[0] - (fx * x / (z * z))[:, None] * rot[2]
    jw1 = (fy / z)[:, None] * rot[1] - (fy * y / (z * z))[:, None] * rot[2]
    a0 = torch.einsum("vk,vkj->vj", jw0, m)
    a1 = torch.einsum("vk,vkj->vj", jw1, m)
    ca = (a0 * a0).sum(-1) + DILATION
    cb = (a0 * a1).sum(-1)
    cc = (a1 * a1).sum(-1) + DILATION
    det = ca * cc - cb * cb
    conic = torch.stack([cc / det, -cb / det, ca / det], -1)
    mean2d = torch.stack([fx * x / z + float(camera.cx), fy * y / z + float(camera.cy)], -1)
    with torch.no_grad():
        mid = 0.5 * (ca + cc)
        lam = mid + torch.sqrt(torch.clamp_min(mid * mid - det, 0.0))
        radius = torch.ceil(SIGMA_SUPPORT * torch.sqrt(lam)).long()
    return Projection(index, mean2d, conic, z, radius)


def _spans(lo: Tensor, hi: Tensor, limit: int) -> tuple[Tensor, Tensor, Tensor]:
    """Integer pixel indices ``k`` with ``lo <= k + 0.5 <= hi`` clipped to ``[0, limit)``, as
    (owner of each index, index, count per owner)."""
    k0 = torch.ceil(lo - 0.5).clamp(0, limit).long()
    k1 = (torch.floor(hi - 0.5).clamp(-1, limit - 1).long() + 1).clamp_min(k0)
    counts = k1 - k0
    total = int(counts.sum())
    owner = torch.repeat_interleave(torch.arange(len(counts), device=lo.device), counts, output_size=total)
    start = torch.cumsum(counts, 0) - counts
    return owner, k0[owner] + torch.arange(total, device=lo.device) - start[owner], counts


def _pairs(proj: Projection, opacity: Tensor, width: int, height: int) -> tuple[Tensor, Tensor, Tensor]:
    """(pixel x, pixel y, Gaussian) of every pair that can reach alpha >= 1/255, Gaussian-major.

    An acceleration only: outside the ellipse ``q <= 2 ln(255 o)`` the alpha is below 1/255, so
    rows are limited to the ellipse's vertical extent and each row to its chord, both intersected
    with the 3-sigma square. A small margin keeps borderline pairs; the caller filters exactly.
    """
    with torch.no_grad():
        m = proj.mean2d.detach()
        con = proj.conic.detach()
        det = con[:, 0] * con[:, 2] - con[:, 1] ** 2  # of the conic, = 1 / det(Sigma2)
        q = 2 * torch.log(torch.clamp_min(opacity.detach() / ALPHA_MIN, 1e-30)) * (1 + 1e-6) + 1e-6
        q = torch.clamp_min(q, 0.0)
        r = proj.radius.to(m.dtype)
        hy = torch.minimum(torch.sqrt(q * con[:, 0] / det), r)  # Sigma2_yy = a / det(conic)
        row_g, row_y, _ = _spans(m[:, 1] - hy, m[:, 1] + hy, height)
        a, b, c = con[row_g].unbind(-1)
        dy = row_y.to(m.dtype) + 0.5 - m[row_g, 1]
        disc = torch.clamp_min((b * dy) ** 2 - a * (c * dy * dy - q[row_g]), 0.0)
        half = torch.sqrt(disc) / a + 1e-4
        centre = -b * dy / a
        rg = r[row_g]
        lo = m[row_g, 0] + torch.maximum(centre - half, -rg)
        hi = m[row_g, 0] + torch.minimum(centre + half, rg)
        row_of_pair, px, _ = _spans(lo, hi, width)
        return px, row_y[row_of_pair], row_g[row_of_pair]


def check_shapes(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, sh: Tensor | None) -> None:
    """A ValueError unless the arguments of a render are [G, 3], [G, 4], [G, 3], [G] and [G, C, 3]
    (``sh`` None: not checked)."""
    g = means.shape[0]
    if means.shape != (g, 3) or quats.shape != (g, 4) or scales.shape != (g, 3) or opacities.shape != (g,):
        raise ValueError(f"shape mismatch: means {tuple(means.shape)}, quats {tuple(quats.shape)}, "
                         f"scales {tuple(scales.shape)}, opacities {tuple(opacities.shape)}; want [G,3], "
                         "[G,4], [G,3], [G]")
    if sh is not None and (sh.ndim != 3 or sh.shape[0] != g or sh.shape[2] != 3 or sh.shape[1] not in (1, 4, 9, 16)):
        raise ValueError(f"sh must be [G, (deg+1)^2, 3] with deg 0..3, got {tuple(sh.shape)}")


def render(
    means: Tensor,  # [G, 3]
    quats: Tensor,  # [G, 4] (w, x, y, z), normalised inside
    scales: Tensor,  # [G, 3] standard deviations
    opacities: Tensor,  # [G] in [0, 1]
    sh: Tensor,  # [G, C, 3], C = (deg+1)^2
    camera: Camera,
    background: tuple[float, float, float] | Tensor = (0.0, 0.0, 0.0),
) -> RenderOutput:
    """Render one camera; differentiable w.r.t. every tensor argument. Device follows ``means``."""
    check_shapes(means, quats, scales, opacities, sh)
    width, height = int(camera.width), int(camera.height)
    dtype, dev = means.dtype, means.device
    bg = torch.as_tensor(background, dtype=dtype, device=dev).reshape(3)

    proj = project(means, quats, scales, camera)
    # visible Gaussians in depth order, so Gaussian-major pairs are already depth-ordered per pixel
    by_depth = torch.argsort(proj.depth.detach(), stable=True)
    proj = Projection(proj.index[by_depth], proj.mean2d[by_depth], proj.conic[by_depth],
                      proj.depth[by_depth], proj.radius[by_depth])
    dirs = means[proj.index] - _camera_tensors(camera, means)[2]
    dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    opac = opacities[proj.index]
    # per visible Gaussian: mean2d (2), conic (3), opacity, depth, colour (3); gathered once per pair
    feat = torch.cat([proj.mean2d, proj.conic, opac[:, None], proj.depth[:, None],
                      eval_sh(sh[proj.index], dirs)], -1)

    px, py, vid = _pairs(proj, opac, width, height)
    with torch.no_grad():  # a stable sort by pixel keeps the Gaussian-major depth order per pixel
        pix, order = torch.sort((py * width + px).to(torch.int32), stable=True)
        pix = pix.long()
        px, py, vid = px.index_select(0, order), py.index_select(0, order), vid.index_select(0, order)

    mx, my, ca, cb, cc, o, z, cr, cg, cbl = torch.index_select(feat.T, 1, vid).unbind(0)
    dx, dy = px.to(dtype) + 0.5 - mx, py.to(dtype) + 0.5 - my
    alpha = o * torch.exp(-0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy)
    # contributions under 1/255 are skipped: zero alpha leaves the transmittance unchanged
    alpha = torch.where(alpha.detach() >= ALPHA_MIN, torch.clamp_max(alpha, ALPHA_MAX), 0.0)

    # transmittance: exclusive cumulative sum of log(1 - a) within each pixel's run, in float64
    # because a global running sum over millions of pairs would lose float32 precision
    log1m = torch.log1p(-alpha.to(torch.float64))
    excl = torch.cumsum(log1m, 0) - log1m
    with torch.no_grad():
        first = torch.ones_like(pix, dtype=torch.bool)
        first[1:] = pix[1:] != pix[:-1]
        run_start = torch.cummax(torch.where(first, torch.arange(len(pix), device=dev), 0), 0).values
    weight = alpha * torch.exp(excl - excl[run_start]).to(dtype)

    values = torch.stack([cr, cg, cbl, torch.ones_like(alpha), z], -1)
    acc = torch.zeros(width * height, 5, dtype=dtype, device=dev).index_add(0, pix, weight[:, None] * values)
    rgb = acc[:, :3] + (1.0 - acc[:, 3:4]) * bg
    return RenderOutput(rgb.reshape(height, width, 3), acc[:, 3].reshape(height, width),
                        acc[:, 4].reshape(height, width))


def render_batch(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, sh: Tensor,
                 cameras: list[Camera], background=(0.0, 0.0, 0.0)) -> RenderOutput:
    """Render several cameras of equal size; outputs are stacked ``[B, H, W, ...]``."""
    outs = [render(means, quats, scales, opacities, sh, cam, background) for cam in cameras]
    return RenderOutput(torch.stack([o.rgb for o in outs]), torch.stack([o.alpha for o in outs]),
                        torch.stack([o.depth for o in outs]))


def render_gaussians(g: Gaussians, camera: Camera, background=(0.0, 0.0, 0.0),
                     device: str | torch.device = "cpu", render_fn=None) -> dict[str, np.ndarray]:
    """Render a :class:`cghair_format.Gaussians` set on the torch ``device`` with ``render_fn`` (a
    function of :func:`render`'s arguments; default :func:`render`); returns numpy ``rgb``, ``alpha``,
    ``depth``. Entry points pass a checked torch.device; a name is checked here."""
    render_fn = render if render_fn is None else render_fn
    if not isinstance(device, torch.device):
        device = torch_device(device)

    def t(a: np.ndarray) -> Tensor:
        return torch.as_tensor(np.ascontiguousarray(a, np.float32), device=device)

    with torch.no_grad():
        out = render_fn(t(g.means), t(g.rotations), t(g.scales), t(g.opacities), t(g.sh), camera, background)
    return {"rgb": out.rgb.cpu().numpy(), "alpha": out.alpha.cpu().numpy(), "depth": out.depth.cpu().numpy()}
