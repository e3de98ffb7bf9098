"""The trainable hair model in torch: card-bound geometry, per-segment opacity, and appearance.

Geometry follows :func:`cghair_format.geometry.strand_points` exactly (same triangles, barycentrics
and interpolated normal) on frozen cards; the trainable part is each point's ``(u, v, delta)``.
Gaussians follow :func:`cghair_format.gaussians.segment_frames`. Appearance by variant:

- ``latents`` (the paper): per card group a codebook of K latents of size D, per strand K logits
  (Gumbel-softmax while training), one global MLP latent -> SH of all the strand's Gaussians;
- ``no-card-clustering``: the same with a single codebook for all cards (N_T = 1);
- ``multi-sh``: our reading of the paper's "multiple SH" row: per group a codebook of K complete
  per-strand SH sets (no latent, no MLP), mixed by the same Gumbel-softmax weights;
- ``single-sh``: one free SH set per strand, shared by all its Gaussians;
- ``unique``: a free SH set per Gaussian (3DGS-style; the upper bound).

Strands of their own point counts (``asset.point_counts``, spec 3) train on the padded ``[S, P]``
coordinates; the Gaussians handed to a renderer are the real segments only (``real_gaussians``, their
indices among the ``S (P-1)``), so placeholders are never drawn and get no gradient.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from cghair_format.asset import Appearance, HairAsset, MlpLayer
from cghair_format.errors import CghError
from cghair_format.gaussians import rgb_to_sh0
from cghair_format.geometry import card_mesh

from . import losses, native_geometry

try:
    from training import _rows
except ImportError:  # not built: segment_rows computes every row
    _rows = None
from cghair_format.codec.schema import MAX_LATENT_DIM

from .config import TrainConfig

WEIGHT_MODES = ("gumbel", "soft", "hard")
INIT_OPACITY = (0.05, 0.9)  # the built asset's opacities are clamped into this range
CODE_INIT_STD = 0.1
SH_REST_INIT_STD = 0.01


class ExportError(CghError, ValueError):
    """A trained model cannot be written as a .cgh (the variant has no compact encoding)."""


class CardGeometry(nn.Module):
    """The frozen card strip mesh, as torch buffers."""

    def __init__(self, asset: HairAsset):
        super().__init__()
        mesh = card_mesh(asset.cards)
        self.segments = asset.cards.segments
        self.register_buffer("vertices", torch.as_tensor(mesh.vertices.astype(np.float32)))
        self.register_buffer("normals", torch.as_tensor(mesh.normals.astype(np.float32)))
        # both side by side [V, 6], so that one gather serves both interpolations (not saved: derived)
        self.register_buffer("vertex_data", torch.cat([self.vertices, self.normals], 1), persistent=False)
        self.register_buffer("triangles", torch.as_tensor(mesh.triangles.astype(np.int64)))
        self.register_buffer("strand_card", torch.as_tensor(asset.strand_card.astype(np.int64)))

    def points(self, uv: Tensor, delta: Tensor) -> Tensor:
        """World points ``[S, P, 3]`` of card coordinates ``uv [S, P, 2]``, ``delta [S, P]``."""
        m = self.segments
        s = uv[..., 0] * m
        with torch.no_grad():
            k = torch.clamp(torch.floor(s), 0, m - 1)
        f = s - k
        v = uv[..., 1]
        upper = (f + v > 1).detach()
        bary = torch.where(upper[..., None], torch.stack([1 - f, f + v - 1, 1 - v], -1),
                           torch.stack([1 - f - v, v, f], -1))
        tri = self.strand_card[:, None] * 2 * m + 2 * k.long() + upper.long()
        corners = self.vertex_data[self.triangles[tri]]  # [S, P, 3 corners, 6]
        # the barycentric sum written out: no [S, P, 3, 6] product materialised, forward or backward
        both = (bary[..., 0:1] * corners[..., 0, :] + bary[..., 1:2] * corners[..., 1, :]
                + bary[..., 2:3] * corners[..., 2, :])
        pos, nrm = both[..., :3], both[..., 3:]
        nrm = nrm / nrm.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        return pos + delta[..., None] * nrm


def segment_gaussians(points: Tensor, thickness: float) -> tuple[Tensor, Tensor, Tensor]:
    """Means, quaternions (w, x, y, z) and scales ``[S*(P-1), ...]`` of strands ``[S, P, 3]``;
    the torch twin of :func:`cghair_format.gaussians.segment_frames`."""
    seg = points[:, 1:] - points[:, :-1]
    length = torch.sqrt((seg * seg).sum(-1).clamp_min(1e-30))
    d = seg / length[..., None]
    zero_len = (seg == 0).all(-1)
    d = torch.where(zero_len[..., None], torch.tensor([0.0, 0.0, 1.0], dtype=d.dtype, device=d.device), d)
    w = 1.0 + d[..., 2]
    q = torch.stack([w, -d[..., 1], d[..., 0], torch.zeros_like(w)], -1)
    q = torch.where((w < 1e-12)[..., None], torch.tensor([0.0, 1.0, 0.0, 0.0], dtype=q.dtype, device=q.device), q)
    q = q / q.norm(dim=-1, keepdim=True)
    thick = torch.full_like(length, thickness)
    scales = torch.stack([thick, thick, torch.where(zero_len, 0.0, length) / 2], -1)
    means = (points[:, 1:] + points[:, :-1]) / 2
    return means.reshape(-1, 3), q.reshape(-1, 4), scales.reshape(-1, 3)


class HairModel(nn.Module):
    """Trainable Gaussians of a card-built asset; see the module docstring for the variants."""

    # the optimiser groups of :meth:`param_groups` whose learning rates decay over a run, and those of
    # the strand points (frozen at first); training.schedule.Schedule reads them
    DECAYING_GROUPS = ("mlp", "codebook", "sh")
    GEOMETRY_GROUPS = ("uv", "delta")

    def __init__(self, asset: HairAsset, config: TrainConfig, base_rgb: tuple[float, float, float] | None = None):
        super().__init__()
        config.validate()
        self._frozen_geometry: tuple[Tensor, Tensor, Tensor] | None = None  # see training_inputs
        self.variant = config.variant
        self.sh_degree = config.sh_degree
        self.thickness = float(asset.thickness)
        s, p = asset.n_strands, asset.points_per_strand
        self.n_strands, self.n_points = s, p
        self.sh_coeffs = (config.sh_degree + 1) ** 2
        self.out_dim = (p - 1) * self.sh_coeffs * 3
        gen = torch.Generator().manual_seed(config.seed)

        self.geometry = CardGeometry(asset)
        # the real segments among the S (P-1) (None: all): what the renderer gets, strand-major
        mask = asset.real_segments() if asset.variable else None
        real = None if mask is None else torch.as_tensor(np.flatnonzero(mask.ravel()))
        self.register_buffer("real_gaussians", real, persistent=False)
        self.register_buffer("real_segments", None if mask is None else torch.as_tensor(mask),
                             persistent=False)  # [S, P-1] bool, or None
        self.uv = nn.Parameter(torch.as_tensor(asset.uvd[..., :2].astype(np.float32)))
        self.delta = nn.Parameter(torch.as_tensor(asset.uvd[..., 2].astype(np.float32)))
        opac = np.clip(asset.opacity.astype(np.float64), *INIT_OPACITY)
        self.opacity_logit = nn.Parameter(torch.as_tensor(np.log(opac / (1 - opac)).astype(np.float32)))

        dc = rgb_to_sh0(np.asarray(base_rgb if base_rgb is not None else (0.3, 0.2, 0.12), np.float64))
        dc_full = np.zeros((p - 1, self.sh_coeffs, 3), np.float32)
        dc_full[:, 0] = dc
        dc_full = torch.as_tensor(dc_full.reshape(-1))

        groups = asset.cards.group.astype(np.int64)[asset.strand_card]
        n_groups = int(asset.cards.group.max()) + 1
        if self.variant == "no-card-clustering":
            groups, n_groups = np.zeros_like(groups), 1
        self.n_groups = n_groups
        self.register_buffer("strand_group", torch.as_tensor(groups))
        k, dim = config.codebook_size, config.latent_dim
        # row of each strand's K codebook entries in the codebooks flattened to [N_T * K, ...]
        self.register_buffer("book_rows", torch.as_tensor(groups)[:, None] * k + torch.arange(k), persistent=False)

        if self.variant in ("latents", "no-card-clustering", "multi-sh"):
            self.logits = nn.Parameter(0.01 * torch.randn(s, k, generator=gen))
        if self.variant in ("latents", "no-card-clustering"):
            self.codebooks = nn.Parameter(CODE_INIT_STD * torch.randn(n_groups, k, dim, generator=gen))
            widths = [dim, *config.mlp_hidden, self.out_dim]
            self.mlp = nn.ModuleList(nn.Linear(a, b) for a, b in zip(widths[:-1], widths[1:], strict=True))
            with torch.no_grad():
                last = self.mlp[-1]
                last.weight.mul_(0.1)
                last.bias.copy_(dc_full)
        elif self.variant == "multi-sh":
            noise = SH_REST_INIT_STD * torch.randn(n_groups, k, self.out_dim, generator=gen)
            self.codebooks = nn.Parameter(dc_full[None, None] + noise)
        elif self.variant == "single-sh":
            noise = SH_REST_INIT_STD * torch.randn(s, self.sh_coeffs * 3, generator=gen)
            self.sh_per_strand = nn.Parameter(dc_full[: self.sh_coeffs * 3][None] + noise)
        elif self.variant == "unique":
            noise = SH_REST_INIT_STD * torch.randn(s, self.out_dim, generator=gen)
            self.sh_per_gaussian = nn.Parameter(dc_full[None] + noise)

    # --- parameters by optimiser group --------------------------------------------------------------

    def param_groups(self, config: TrainConfig, scene_scale: float) -> list[dict]:
        groups = [
            {"name": "uv", "params": [self.uv], "lr": config.lr_geometry},
            {"name": "delta", "params": [self.delta], "lr": config.lr_geometry * scene_scale},
            {"name": "opacity", "params": [self.opacity_logit], "lr": config.lr_opacity},
        ]
        if hasattr(self, "logits"):
            groups.append({"name": "logits", "params": [self.logits], "lr": config.lr_logits})
        if self.variant in ("latents", "no-card-clustering"):
            groups.append({"name": "codebook", "params": [self.codebooks], "lr": config.lr_codebook})
            groups.append({"name": "mlp", "params": list(self.mlp.parameters()), "lr": config.lr_mlp})
        elif self.variant == "multi-sh":
            groups.append({"name": "codebook", "params": [self.codebooks], "lr": config.lr_sh})
        elif self.variant == "single-sh":
            groups.append({"name": "sh", "params": [self.sh_per_strand], "lr": config.lr_sh})
        else:
            groups.append({"name": "sh", "params": [self.sh_per_gaussian], "lr": config.lr_sh})
        return groups

    def set_geometry_trainable(self, trainable: bool) -> None:
        self.uv.requires_grad_(trainable)
        self.delta.requires_grad_(trainable)
        if trainable:
            self._frozen_geometry = None

    def training_inputs(self, tau: float) -> tuple[Tensor, Tensor, Tensor, Tensor, Callable[[Tensor | None], Tensor]]:
        """``(means, quats, scales, opacities, sh_source)`` of one training step, the codebook weights
        drawn by Gumbel-softmax at ``tau``. While the geometry is frozen (:meth:`set_geometry_trainable`)
        the Gaussians' positions are computed once and reused. The SH come as :meth:`sh_source`: the
        native backend runs it for the Gaussians it shows only."""
        if self.uv.requires_grad:
            geometry = self.gaussian_geometry()
        else:
            if self._frozen_geometry is None:
                with torch.no_grad():
                    self._frozen_geometry = self.gaussian_geometry()
            geometry = self._frozen_geometry
        sh = self.sh_source("gumbel", tau)
        return (*geometry, self.gaussian_opacities(), sh)

    def opacity_smoothness(self) -> Tensor:
        """The opacity smoothness loss term (:func:`training.losses.opacity_smoothness`) of the real segments."""
        return losses.opacity_smoothness(self.opacities(), self.real_segments)

    # --- forward ------------------------------------------------------------------------------------

    def weights(self, mode: str, tau: float) -> Tensor:
        """Codebook weights ``[S, K]``: Gumbel-softmax (training), softmax(logits / tau) or one-hot."""
        if mode == "gumbel":
            return F.gumbel_softmax(self.logits, tau=tau, hard=False)
        if mode == "soft":
            return torch.softmax(self.logits / tau, dim=-1)
        if mode == "hard":
            return F.one_hot(self.logits.argmax(-1), self.logits.shape[1]).to(self.logits.dtype)
        raise ValueError(f"weight mode must be one of {WEIGHT_MODES}, got {mode!r}")

    def mix(self, weights: Tensor) -> Tensor:
        """``sum_k weights[s, k] codebooks[group(s), k]``, ``[S, ...]``, without gathering ``[S, K, ...]``."""
        books = self.codebooks.reshape(-1, self.codebooks.shape[-1])
        return F.embedding_bag(self.book_rows, books, per_sample_weights=weights, mode="sum")

    def strand_sh(self, mode: str = "gumbel", tau: float = 1.0) -> Tensor:
        """SH ``[G, C, 3]`` of every (real) Gaussian, strand-major."""
        return self.sh_source(mode, tau)(None)

    def sh_source(self, mode: str = "gumbel", tau: float = 1.0) -> Callable[[Tensor | None], Tensor]:
        """A function from Gaussian indices ``[n]`` (strand-major, among the real ones; None: all) to
        their SH ``[n, C, 3]``, with the codebook weights drawn once, now. For the MLP variants it runs
        the last layer only for the Gaussians asked for: a renderer that asks only for those it shows
        (the native splatter) skips most of the model's work and memory in dense hair."""
        per_gaussian = self.sh_coeffs * 3
        if self.variant in ("latents", "no-card-clustering"):
            hidden = self.mix(self.weights(mode, tau))
            for layer in self.mlp[:-1]:
                hidden = torch.relu(layer(hidden))
            last = self.mlp[-1]

            def rows(index: Tensor | None) -> Tensor:
                if index is None:
                    return last(hidden)
                return segment_rows(hidden, last.weight, last.bias, index, self.n_points - 1)
        elif self.variant == "multi-sh":
            mixed = self.mix(self.weights(mode, tau)).reshape(-1, per_gaussian)

            def rows(index: Tensor | None) -> Tensor:
                return mixed if index is None else mixed[index]
        elif self.variant == "single-sh":
            def rows(index: Tensor | None) -> Tensor:
                if index is None:
                    return self.sh_per_strand.repeat(1, self.n_points - 1)
                return self.sh_per_strand[torch.div(index, self.n_points - 1, rounding_mode="floor")]
        else:
            def rows(index: Tensor | None) -> Tensor:
                every = self.sh_per_gaussian.reshape(-1, per_gaussian)
                return every if index is None else every[index]
        real = self.real_gaussians
        if real is None:
            return lambda index: rows(index).reshape(-1, self.sh_coeffs, 3)
        # real-Gaussian indices to their (strand, segment) rows s (P-1) + i
        return lambda index: rows(real if index is None else real[index]).reshape(-1, self.sh_coeffs, 3)

    def points(self) -> Tensor:
        return self.geometry.points(self.uv, self.delta)

    def gaussian_geometry(self) -> tuple[Tensor, Tensor, Tensor]:
        """Means, quaternions and scales of all (real) Gaussians (by the compiled kernel where it can run)."""
        if native_geometry.usable(self.uv, self.delta, self.geometry.vertex_data):
            padded = native_geometry.segment_gaussians(self.geometry, self.uv, self.delta, self.thickness)
        else:
            padded = segment_gaussians(self.points(), self.thickness)
        return padded if self.real_gaussians is None else tuple(x.index_select(0, self.real_gaussians)
                                                                for x in padded)

    def forward(self, mode: str = "gumbel", tau: float = 1.0,
                geometry: tuple[Tensor, Tensor, Tensor] | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        """``(means, quats, scales, opacities, sh)`` of all (real) Gaussians, ready for the splatter.
        ``geometry`` reuses a :meth:`gaussian_geometry` computed earlier (while it is frozen)."""
        means, quats, scales = geometry if geometry is not None else self.gaussian_geometry()
        return means, quats, scales, self.gaussian_opacities(), self.strand_sh(mode, tau)

    def opacities(self) -> Tensor:
        return torch.sigmoid(self.opacity_logit)  # [S, P-1], placeholders included

    def gaussian_opacities(self) -> Tensor:
        """The opacities ``[G]`` of the (real) Gaussians, as :meth:`gaussian_geometry` orders them."""
        flat = self.opacities().reshape(-1)
        return flat if self.real_gaussians is None else flat.index_select(0, self.real_gaussians)

    @property
    def n_gaussians(self) -> int:
        return self.n_strands * (self.n_points - 1) if self.real_gaussians is None else len(self.real_gaussians)

    # --- sizes and export ---------------------------------------------------------------------------

    def appearance_parameters(self) -> int:
        """Number of stored appearance values (logits, codebooks, MLP or free SH)."""
        names = ("logits", "codebooks", "sh_per_strand", "sh_per_gaussian")
        n = sum(getattr(self, a).numel() for a in names if hasattr(self, a))
        if hasattr(self, "mlp"):
            n += sum(p.numel() for p in self.mlp.parameters())
        return int(n)

    def appearance_bytes(self) -> int:
        return 4 * self.appearance_parameters()  # float32

    def export_refusal(self) -> str | None:
        """Why this model cannot be written as a .cgh (None: it can)."""
        if self.variant in ("unique", "single-sh"):
            per = "Gaussian" if self.variant == "unique" else "strand"
            return (f"variant {self.variant!r} stores free SH per {per}; the .cgh format stores only codebooks "
                    "+ MLP, so it cannot be written (use --variant latents, multi-sh or no-card-clustering)")
        if self.variant == "multi-sh" and self.out_dim > MAX_LATENT_DIM:
            return (f"multi-sh needs codebook entries of {self.out_dim} values; the format allows {MAX_LATENT_DIM} "
                    "(fewer points per strand or a lower SH degree fit)")
        return None

    def to_asset(self, base: HairAsset, mode: str = "soft", tau: float = 1.0) -> HairAsset:
        """The trained model as a :class:`HairAsset` (cards of ``base``, trained coordinates,
        opacities and appearance). ``mode`` is the stored weight mode, "soft" or "hard"."""
        if mode not in ("soft", "hard"):
            raise ValueError(f"export weight mode must be soft or hard, got {mode!r}")
        refusal = self.export_refusal()
        if refusal is not None:
            raise ExportError(refusal)
        cards = base.cards
        if self.variant == "no-card-clustering":
            cards = type(cards)(cards.spine, cards.normal, cards.half_width, np.zeros_like(cards.group))
        logits = self.logits.detach().cpu().numpy().astype(np.float32)
        books = self.codebooks.detach().cpu().numpy().astype(np.float32)
        if self.variant == "multi-sh":
            layers = [MlpLayer(np.eye(self.out_dim, dtype=np.float32), np.zeros(self.out_dim, np.float32), "none")]
        else:
            layers = [MlpLayer(layer.weight.detach().cpu().numpy().astype(np.float32),
                               layer.bias.detach().cpu().numpy().astype(np.float32),
                               "relu" if i < len(self.mlp) - 1 else "none")
                      for i, layer in enumerate(self.mlp)]
        appearance = Appearance(logits, books, layers, sh_degree=self.sh_degree, weight_mode=mode,
                                temperature=float(tau))
        uvd = torch.cat([self.uv, self.delta[..., None]], -1).detach().cpu().numpy().astype(np.float32)
        opacity = self.opacities().detach().cpu().numpy().astype(np.float32)
        return HairAsset(cards=cards, strand_card=base.strand_card, uvd=uvd, opacity=opacity,
                         appearance=appearance, thickness=base.thickness, meters_per_unit=base.meters_per_unit,
                         up_axis=base.up_axis, generator="cghair train", attribution=base.attribution,
                         strand_ids=base.strand_ids, root_uv=base.root_uv, source_color=base.source_color,
                         metadata=dict(base.metadata), point_counts=base.point_counts).validate()


class _SegmentRows(torch.autograd.Function):
    """:func:`segment_rows` through the compiled kernel (training/_rows.pyx)."""

    @staticmethod
    def forward(ctx, hidden, weight, bias, index, segments):
        width = weight.shape[0] // segments
        strand = torch.div(index, segments, rounding_mode="floor")
        block = index - strand * segments
        by_block = torch.argsort(block, stable=True)
        h = hidden.detach().contiguous()
        w = weight.detach().reshape(segments, width, -1)
        out = hidden.new_empty((len(index), width))
        _rows.forward(h.numpy(), w.transpose(1, 2).contiguous().numpy(),
                      bias.detach().reshape(segments, width).contiguous().numpy(), strand.numpy(), block.numpy(),
                      by_block.numpy(), out.numpy())
        ctx.save_for_backward(h, w, strand, block, by_block)
        return out

    @staticmethod
    def backward(ctx, grad):
        h, w, strand, block, by_block = ctx.saved_tensors
        segments, width, _ = w.shape
        block_start = torch.zeros(segments + 1, dtype=torch.int64)
        block_start[1:] = torch.cumsum(torch.bincount(block, minlength=segments), 0)
        grad_rows = h.new_empty((len(strand), h.shape[1]))
        g_weight, g_bias = torch.zeros_like(w), h.new_zeros((segments, width))
        _rows.backward(h.numpy(), w.contiguous().numpy(), strand.numpy(), block.numpy(), by_block.numpy(),
                       block_start.numpy(), grad.contiguous().float().numpy(), grad_rows.numpy(), g_weight.numpy(),
                       g_bias.numpy())
        g_hidden = torch.zeros_like(h).index_add_(0, strand, grad_rows)
        return g_hidden, g_weight.reshape(-1, h.shape[1]), g_bias.reshape(-1), None, None


def segment_rows(hidden: Tensor, weight: Tensor, bias: Tensor, index: Tensor, segments: int) -> Tensor:
    """Rows ``index`` of ``hidden @ weight.T + bias`` viewed as ``[S * segments, out / segments]``
    (Gaussian ``i`` is strand ``i // segments``'s block ``i % segments``), computing only those
    where the compiled kernel runs (float32 on the CPU), else all of them."""
    if _rows is None or any(t.device.type != "cpu" or t.dtype != torch.float32 for t in (hidden, weight, bias)):
        return F.linear(hidden, weight, bias).reshape(-1, weight.shape[0] // segments)[index]
    return _SegmentRows.apply(hidden, weight, bias, index, segments)


def tau_at(config: TrainConfig, iteration: int) -> float:
    """The Gumbel-softmax temperature: exponential from tau_start to tau_end over the run."""
    frac = min(1.0, iteration / max(1, config.iterations))
    return config.tau_start * math.exp(frac * math.log(config.tau_end / config.tau_start))
