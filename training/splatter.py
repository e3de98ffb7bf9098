"""The reference 3D Gaussian splatter: pure torch, differentiable, CPU and CUDA.

This is the source of truth for the image model shared with the viewer (see the rendering
contract): EWA projection with a 0.3 px^2 dilation, alpha = min(0.99, o exp(-q/2)) with
contributions under 1/255 skipped, a 3-sigma square support, colour from SH per Gaussian and
front-to-back compositing in camera-depth order.

Cost grows with the pixels each Gaussian covers, not with pixels x Gaussians: every Gaussian's
support square is expanded into (pixel, Gaussian) pairs, the pairs are sorted by one key
(pixel, depth rank), and the transmittance of each pair is a segmented exclusive cumulative sum
of ``log(1 - alpha)`` within its pixel's run. Autograd differentiates all of it.

Support rule (both renderers): with ``r = ceil(3 sqrt(lambda_max(Sigma2)))``, Gaussian ``g``
touches pixel ``(i, j)`` iff ``|i + 0.5 - m_x| <= r`` and ``|j + 0.5 - m_y| <= r``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

if TYPE_CHECKING:
    from cghair_format.camera import Camera
    from cghair_format.gaussians import Gaussians

NEAR_PLANE = 0.01  # camera-space z below which a Gaussian is culled
DILATION = 0.3  # px^2 added to the 2D covariance's diagonal (low-pass filter)
ALPHA_MAX = 0.99  # per-contribution alpha clamp
ALPHA_MIN = 1.0 / 255.0  # contributions below this are skipped
SIGMA_SUPPORT = 3.0  # support half-size in standard deviations (largest axis)

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


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
    """RGB ``[G, 3]`` from SH ``[G, (deg+1)^2, 3]`` and unit directions ``[G, 3]`` (3DGS convention).

    Same polynomial as :func:`cghair_format.gaussians.eval_sh`: ``max(0, sum c_lm Y_lm + 0.5)``.
    """
    deg = int(round(math.sqrt(sh.shape[1]))) - 1
    res = SH_C0 * sh[:, 0]
    if deg > 0:
        x, y, z = (dirs[:, i:i + 1] for i in range(3))
        res = res - SH_C1 * y * sh[:, 1] + SH_C1 * z * sh[:, 2] - SH_C1 * x * sh[:, 3]
        if deg > 1:
            xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
            res = (res + SH_C2[0] * xy * sh[:, 4] + SH_C2[1] * yz * sh[:, 5]
                   + SH_C2[2] * (2 * zz - xx - yy) * sh[:, 6] + SH_C2[3] * xz * sh[:, 7]
                   + SH_C2[4] * (xx - yy) * sh[:, 8])
            if deg > 2:
                res = (res + SH_C3[0] * y * (3 * xx - yy) * sh[:, 9] + SH_C3[1] * xy * z * sh[:, 10]
                       + SH_C3[2] * y * (4 * zz - xx - yy) * sh[:, 11]
                       + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
                       + SH_C3[4] * x * (4 * zz - xx - yy) * sh[:, 13]
                       + SH_C3[5] * z * (xx - yy) * sh[:, 14] + SH_C3[6] * x * (xx - 3 * yy) * sh[:, 15])
    return torch.clamp_min(res + 0.5, 0.0)


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
    zero = torch.zeros_like(z)
    jac = torch.stack([fx / z, zero, -fx * x / (z * z), zero, fy / z, -fy * y / (z * z)], -1)
    jac = jac.reshape(-1, 2, 3)
    m = quat_to_rotmat(quats[index]) * scales[index][:, None, :]  # R_q S
    a = jac @ (rot @ m)  # [V, 2, 3]
    cov = a @ a.transpose(1, 2)
    ca = cov[:, 0, 0] + DILATION
    cb = cov[:, 0, 1]
    cc = cov[:, 1, 1] + DILATION
    det = ca * cc - cb * cb
    conic = torch.stack([cc / det, -cb / det, ca / det], -1)
    mean2d = torch.stack([fx * x / z + float(camera.cx), fy * y / z + float(camera.cy)], -1)
    with torch.no_grad():
        mid = 0.5 * (ca + cc)
        lam = mid + torch.sqrt(torch.clamp_min(mid * mid - det, 0.0))
        radius = torch.ceil(SIGMA_SUPPORT * torch.sqrt(lam)).long()
    return Projection(index, mean2d, conic, z, radius)


def _pairs(proj: Projection, width: int, height: int) -> tuple[Tensor, Tensor]:
    """(pixel id, visible-Gaussian id) of every pixel centre inside each Gaussian's support square."""
    with torch.no_grad():
        m = proj.mean2d.detach()
        r = proj.radius.to(m.dtype)
        # pixel i is inside iff m - r <= i + 0.5 <= m + r
        x0 = torch.ceil(m[:, 0] - r - 0.5).clamp(0, width).long()
        x1 = torch.floor(m[:, 0] + r - 0.5).clamp(-1, width - 1).long() + 1
        y0 = torch.ceil(m[:, 1] - r - 0.5).clamp(0, height).long()
        y1 = torch.floor(m[:, 1] + r - 0.5).clamp(-1, height - 1).long() + 1
        bw = (x1 - x0).clamp_min(0)
        bh = (y1 - y0).clamp_min(0)
        counts = bw * bh
        total = int(counts.sum())
        dev = m.device
        if total == 0:
            empty = torch.zeros(0, dtype=torch.long, device=dev)
            return empty, empty
        gid = torch.repeat_interleave(torch.arange(len(counts), device=dev), counts, output_size=total)
        start = torch.cumsum(counts, 0) - counts
        local = torch.arange(total, device=dev) - start[gid]
        bwg = bw[gid]
        px = x0[gid] + local % bwg
        py = y0[gid] + local // bwg
        return py * width + px, gid


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
    g = means.shape[0]
    if means.shape != (g, 3) or quats.shape != (g, 4) or scales.shape != (g, 3) or opacities.shape != (g,):
        raise ValueError(f"shape mismatch: means {tuple(means.shape)}, quats {tuple(quats.shape)}, "
                         f"scales {tuple(scales.shape)}, opacities {tuple(opacities.shape)}; want [G,3], "
                         "[G,4], [G,3], [G]")
    if sh.ndim != 3 or sh.shape[0] != g or sh.shape[2] != 3 or sh.shape[1] not in (1, 4, 9, 16):
        raise ValueError(f"sh must be [G, (deg+1)^2, 3] with deg 0..3, got {tuple(sh.shape)}")
    width, height = int(camera.width), int(camera.height)
    n_pix = width * height
    dtype, dev = means.dtype, means.device
    bg = torch.as_tensor(background, dtype=dtype, device=dev).reshape(3)

    proj = project(means, quats, scales, camera)
    pix, vid = _pairs(proj, width, height)

    # alpha per pair; drop the ones under 1/255 before sorting (the cut is not differentiated)
    centre = torch.stack([(pix % width).to(dtype) + 0.5, (pix // width).to(dtype) + 0.5], -1)
    d = centre - proj.mean2d[vid]
    con = proj.conic[vid]
    power = -0.5 * (con[:, 0] * d[:, 0] ** 2 + con[:, 2] * d[:, 1] ** 2) - con[:, 1] * d[:, 0] * d[:, 1]
    alpha = torch.clamp_max(opacities[proj.index][vid] * torch.exp(power), ALPHA_MAX)
    keep = torch.nonzero(alpha.detach() >= ALPHA_MIN).squeeze(1)
    pix, vid, alpha = pix[keep], vid[keep], alpha[keep]

    # one sort by (pixel, depth rank)
    n_vis = proj.depth.shape[0]
    rank = torch.empty(n_vis, dtype=torch.long, device=dev)
    rank[torch.argsort(proj.depth.detach(), stable=True)] = torch.arange(n_vis, device=dev)
    order = torch.argsort(pix * max(n_vis, 1) + rank[vid])
    pix, vid, alpha = pix[order], vid[order], alpha[order]

    # transmittance: exclusive cumulative sum of log(1 - a) within each pixel's run, in float64
    # because a global running sum over millions of pairs would lose float32 precision
    log1m = torch.log1p(-alpha.to(torch.float64))
    incl = torch.cumsum(log1m, 0)
    excl = incl - log1m
    first = torch.ones_like(pix, dtype=torch.bool)
    first[1:] = pix[1:] != pix[:-1]
    run_start = torch.cummax(torch.where(first, torch.arange(len(pix), device=dev), 0), 0).values
    trans = torch.exp(excl - excl[run_start]).to(dtype)
    weight = alpha * trans

    dirs = means[proj.index] - _camera_tensors(camera, means)[2]
    dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    colour = eval_sh(sh[proj.index], dirs)  # [V, 3]

    rgb = torch.zeros(n_pix, 3, dtype=dtype, device=dev).index_add(0, pix, weight[:, None] * colour[vid])
    acc = torch.zeros(n_pix, dtype=dtype, device=dev).index_add(0, pix, weight)
    depth = torch.zeros(n_pix, dtype=dtype, device=dev).index_add(0, pix, weight * proj.depth[vid])
    rgb = rgb + (1.0 - acc)[:, None] * bg
    return RenderOutput(rgb.reshape(height, width, 3), acc.reshape(height, width),
                        depth.reshape(height, width))


def render_batch(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, sh: Tensor,
                 cameras: list[Camera], background=(0.0, 0.0, 0.0)) -> RenderOutput:
    """Render several cameras of equal size; outputs are stacked ``[B, H, W, ...]``."""
    outs = [render(means, quats, scales, opacities, sh, cam, background) for cam in cameras]
    return RenderOutput(torch.stack([o.rgb for o in outs]), torch.stack([o.alpha for o in outs]),
                        torch.stack([o.depth for o in outs]))


def render_gaussians(g: Gaussians, camera: Camera, background=(0.0, 0.0, 0.0),
                     device: str | torch.device = "cpu") -> dict[str, np.ndarray]:
    """Render a :class:`cghair_format.Gaussians` set; returns numpy ``rgb``, ``alpha``, ``depth``."""
    def t(a: np.ndarray) -> Tensor:
        return torch.as_tensor(np.ascontiguousarray(a, np.float32), device=device)

    with torch.no_grad():
        out = render(t(g.means), t(g.rotations), t(g.scales), t(g.opacities), t(g.sh), camera, background)
    return {"rgb": out.rgb.cpu().numpy(), "alpha": out.alpha.cpu().numpy(), "depth": out.depth.cpu().numpy()}
