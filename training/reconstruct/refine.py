"""Joint refinement of grown strands through the differentiable splatter.

Every strand point but the root moves; each strand also gets a colour. Per iteration, on a few
training views: photometric L1 (premultiplied RGB), mask L1 (rendered alpha against the hair
mask), an orientation loss (``conf * sin^2`` of the angle between each projected segment and the
2D orientation map at its midpoint), and a shape prior: the strands' distance from the PCA basis
of :mod:`.prior`, plus terms that keep the grown strands' segment lengths and bending (second
differences) and pull weakly towards them.
"""

from __future__ import annotations

import numpy as np
import torch

from cghair_format.gaussians import SH_C0
from cghair_format.strands import Strands

from ..backends import renderer, resolve_backend
from ..model import segment_gaussians
from .orientation import OrientationMap
from .prior import StrandPrior, canonical_frames

VIEWS_PER_ITER = 2
LR_VOXELS = 0.05  # Adam step for the points, in units of the strands' mean segment length
LR_COLOUR = 0.02
W_MASK = 1.0
W_ORIENT = 0.1
W_LENGTH = 1.0
W_BEND = 1.0
W_ANCHOR = 0.01
W_PRIOR = 0.1
OPACITY = 0.9
THICKNESS_OF_SEGMENT = 0.15  # Gaussian radius as a fraction of the mean segment length


def _orientation_loss(points: torch.Tensor, cam, m: OrientationMap) -> torch.Tensor:
    w2c = torch.as_tensor(cam.world_to_camera, dtype=points.dtype)
    pc = points.reshape(-1, 3) @ w2c[:3, :3].T + w2c[:3, 3]
    z = pc[:, 2].clamp_min(1e-6)
    uv = torch.stack([cam.fx * pc[:, 0] / z + cam.cx, cam.fy * pc[:, 1] / z + cam.cy], -1).reshape(*points.shape[:2], 2)
    seg = uv[:, 1:] - uv[:, :-1]
    mid = ((uv[:, 1:] + uv[:, :-1]) / 2).detach().reshape(-1, 2).numpy()
    h, w = m.angle.shape
    px, py = mid[:, 0].astype(int), mid[:, 1].astype(int)
    ok = (px >= 0) & (px < w) & (py >= 0) & (py < h)
    px, py = np.clip(px, 0, w - 1), np.clip(py, 0, h - 1)
    conf = torch.as_tensor(np.where(ok, m.confidence[py, px], 0.0), dtype=points.dtype)
    ang = torch.as_tensor(m.angle[py, px], dtype=points.dtype)
    t = torch.stack([torch.cos(ang), torch.sin(ang)], -1)
    s = seg.reshape(-1, 2)
    s = s / s.norm(dim=-1, keepdim=True).clamp_min(1e-9)
    cross = s[:, 0] * t[:, 1] - s[:, 1] * t[:, 0]  # sin of the angle between them
    return (conf * cross * cross).sum() / conf.sum().clamp_min(1e-9)


def _prior_loss(pts: torch.Tensor, prior: StrandPrior, up: np.ndarray, scale: float) -> torch.Tensor:
    """Mean squared distance (per point, in units of ``scale`` metres) of strands from the basis;
    the canonical frames are held fixed within a step."""
    idx = np.linspace(0, pts.shape[1] - 1, prior.points).round().astype(int)
    sub = pts[:, idx] * scale
    frames = torch.as_tensor(canonical_frames(sub.detach().double().numpy(), up), dtype=pts.dtype)
    flat = torch.einsum("sij,spj->spi", frames, sub - sub[:, :1]).reshape(len(sub), -1)
    d = flat - torch.as_tensor(prior.mean, dtype=pts.dtype)
    comp = torch.as_tensor(prior.components, dtype=pts.dtype)
    r = d - (d @ comp.T) @ comp
    return r.pow(2).mean() * 3


def refine_strands(grown: Strands, views, maps: list[OrientationMap], cfg, up: np.ndarray,
                   strand_prior: StrandPrior | None = None, log=print) -> tuple[Strands, list[float]]:
    """``cfg.refine_iters`` Adam steps (see the module docstring); returns the strands and the loss
    history (mean of each tenth of the run)."""
    render = renderer(resolve_backend(cfg.backend))
    base = torch.as_tensor(grown.to_array(), dtype=torch.float32)
    seg0 = (base[:, 1:] - base[:, :-1]).norm(dim=-1)
    mean_seg = float(seg0.mean())
    bend0 = base[:, 2:] - 2 * base[:, 1:-1] + base[:, :-2]
    delta = torch.zeros_like(base[:, 1:], requires_grad=True)
    hair = np.concatenate([v.image[..., :3][v.image[..., 3] > 0.5] for v in views])
    rgb0 = torch.as_tensor(np.tile(hair.mean(0), (len(base), 1)), dtype=torch.float32)
    colour = torch.logit(rgb0.clamp(0.02, 0.98)).requires_grad_(True)
    opt = torch.optim.Adam([{"params": [delta], "lr": LR_VOXELS * mean_seg},
                            {"params": [colour], "lr": LR_COLOUR}])
    targets = [torch.as_tensor(v.premultiplied(), dtype=torch.float32) for v in views]
    masks = [torch.as_tensor((v.image[..., 3] > 0.5).astype(np.float32)) for v in views]
    rng = np.random.default_rng(cfg.seed)
    thickness = THICKNESS_OF_SEGMENT * mean_seg
    opac = torch.full((len(base) * (base.shape[1] - 1),), OPACITY)
    hist, chunk = [], []
    every = max(1, cfg.refine_iters // 10)
    for it in range(cfg.refine_iters):
        pts = torch.cat([base[:, :1], base[:, 1:] + delta], 1)
        means, quats, scales = segment_gaussians(pts, thickness)
        seg_rgb = torch.sigmoid(colour).repeat_interleave(base.shape[1] - 1, 0)
        sh = ((seg_rgb - 0.5) / SH_C0)[:, None]
        loss = 0.0
        for k in rng.choice(len(views), min(VIEWS_PER_ITER, len(views)), replace=False):
            out = render(means, quats, scales, opac, sh, views[k].camera, (0.0, 0.0, 0.0))
            loss = loss + (out.rgb - targets[k]).abs().mean() + W_MASK * (out.alpha - masks[k]).abs().mean()
            loss = loss + W_ORIENT * _orientation_loss(pts, views[k].camera, maps[k])
        seg = (pts[:, 1:] - pts[:, :-1]).norm(dim=-1)
        bend = pts[:, 2:] - 2 * pts[:, 1:-1] + pts[:, :-2]
        shape = (W_LENGTH * ((seg - seg0) / mean_seg).pow(2).mean()
                 + W_BEND * ((bend - bend0) / mean_seg).pow(2).sum(-1).mean()
                 + W_ANCHOR * (delta / mean_seg).pow(2).sum(-1).mean())
        if strand_prior is not None:
            metres = mean_seg * grown.meters_per_unit
            shape = shape + W_PRIOR * _prior_loss(pts, strand_prior, up, grown.meters_per_unit) / metres ** 2
        loss = loss / VIEWS_PER_ITER + shape
        opt.zero_grad()
        loss.backward()
        opt.step()
        chunk.append(float(loss.detach()))
        if len(chunk) == every or it == cfg.refine_iters - 1:
            hist.append(float(np.mean(chunk)))
            log(f"[refine] iteration {it + 1}/{cfg.refine_iters}: loss {hist[-1]:.4f}")
            chunk = []
    pts = torch.cat([base[:, :1], base[:, 1:] + delta], 1).detach().numpy()
    return Strands.from_array(pts, meters_per_unit=grown.meters_per_unit, up_axis=grown.up_axis), hist
