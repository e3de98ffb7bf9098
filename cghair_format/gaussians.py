"""Gaussians of a hair asset (spec: "Gaussians", "Appearance").

One cylindrical Gaussian per strand segment ``p_i -> p_i+1``: mean at the midpoint, local z axis
along the segment, scales ``(d, d, |p_i+1 - p_i| / 2)``, the segment's opacity, and SH colour
coefficients from the appearance model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _decoder, memory
from .asset import Appearance, HairAsset
from .errors import CghError
from .geometry import strand_points
from .parallel import map_blocks
from .strands import Strands

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


@dataclass
class Gaussians:
    """A flat set of ``G`` 3D Gaussians, in the layout splatters use."""

    means: np.ndarray  # [G, 3] float32
    rotations: np.ndarray  # [G, 4] float32 unit quaternions (w, x, y, z)
    scales: np.ndarray  # [G, 3] float32 standard deviations along the local axes
    opacities: np.ndarray  # [G] float32 in [0, 1]
    sh: np.ndarray  # [G, (deg+1)^2, 3] float32, real SH coefficients per RGB channel

    @property
    def count(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        return int(round(np.sqrt(self.sh.shape[1]))) - 1


def segment_frames(points: np.ndarray, thickness: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Means, rotations (w, x, y, z) and scales of the segment Gaussians of strands ``[S, P, 3]``.

    The rotation is the shortest arc taking +z to the segment direction; a zero-length segment
    gets the identity, a segment along -z a half turn about x (compiled: :func:`._decoder.segment_frames`).
    """
    s, p = points.shape[:2]
    points = np.ascontiguousarray(points, np.float32)
    means = np.empty((s, p - 1, 3), np.float32)
    rotations = np.empty((s, p - 1, 4), np.float32)
    scales = np.empty((s, p - 1, 3), np.float32)

    def block(b: slice) -> None:
        _decoder.segment_frames(points[b], float(thickness), means[b], rotations[b], scales[b])

    map_blocks(block, s)
    return means.reshape(-1, 3), rotations.reshape(-1, 4), scales.reshape(-1, 3)


def strand_weights(appearance: Appearance) -> np.ndarray:
    """Codebook weights ``[S, K]``: softmax of logits / temperature, or one-hot of the argmax."""
    logits = appearance.logits.astype(np.float64)
    if appearance.weight_mode == "hard":
        w = np.zeros_like(logits)
        w[np.arange(len(logits)), np.argmax(logits, axis=1)] = 1.0
        return w
    z = logits / appearance.temperature
    z -= z.max(axis=1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)


def strand_latents(appearance: Appearance, strand_group: np.ndarray) -> np.ndarray:
    """Each strand's latent ``[S, D]``: its weights over its card group's codebook (one small matrix
    product per group, over that group's strands)."""
    w = strand_weights(appearance)
    codebooks = appearance.codebooks.astype(np.float64)
    group = np.asarray(strand_group, np.int64)
    order = np.argsort(group, kind="stable")
    bounds = np.searchsorted(group[order], np.arange(appearance.n_groups + 1))
    latents = np.empty((len(group), appearance.latent_dim))
    for g in range(appearance.n_groups):
        members = order[bounds[g]:bounds[g + 1]]
        latents[members] = w[members] @ codebooks[g]
    return latents


def run_mlp(appearance: Appearance, latents: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """The global MLP applied to latents ``[S, D]``, in float32; ``[S, out]``. Each layer is one matrix
    product over all strands, its bias included (a column of ones on the input: a large model's last
    layer writes its output of hundreds of MB once, in :func:`.memory.empty`); BLAS runs it on every
    core, which runs steadier than our threads calling BLAS on blocks. A ReLU then runs in place, by
    blocks of strands on every core. ``out``: the last layer's output ``[S, out]``, where made already."""
    h = latents.astype(np.float32)
    for i, layer in enumerate(appearance.mlp):
        x = np.concatenate([h, np.ones((len(h), 1), np.float32)], axis=1)
        w = np.concatenate([layer.weight.astype(np.float32).T, layer.bias.astype(np.float32)[None, :]])
        last = out is not None and i == len(appearance.mlp) - 1
        h = np.matmul(x, w, out=out if last else memory.empty((len(h), w.shape[1]), np.float32))
        if layer.activation == "relu":
            map_blocks(lambda b, h=h: np.maximum(h[b], 0, out=h[b]), len(h))
    return h


def strand_sh(asset: HairAsset, out: np.ndarray | None = None) -> np.ndarray:
    """SH coefficients ``[S, P-1, (deg+1)^2, 3]`` of every Gaussian, from the appearance model; written
    into ``out`` (float32 ``[S, (P-1) (deg+1)^2 3]``) where given."""
    app = asset.appearance
    group = asset.cards.group.astype(np.int64)[asset.strand_card]
    sh = run_mlp(app, strand_latents(app, group), out)
    return sh.reshape(asset.n_strands, asset.points_per_strand - 1, app.sh_coeffs, 3)


def decode_points(asset: HairAsset) -> np.ndarray:
    """World positions ``[S, P, 3]`` of all strand points, for an asset whose strands all have ``P``
    points; a variable-count asset is refused (its padded array would hand out placeholders as points):
    :func:`decode_strands` gives any asset's strands."""
    if asset.variable:
        raise CghError(f"the asset's strands have {asset.counts.min()} to {asset.points_per_strand} points: "
                       "decode_points returns equal-length strands only, use decode_strands(asset)")
    return strand_points(asset.cards, asset.strand_card, asset.uvd)


def decode_strands(asset: HairAsset) -> Strands:
    """Every strand's own points (placeholders dropped), flat with offsets, with the source colours and
    root UVs where the asset has them."""
    real = asset.real_points().ravel()
    points = strand_points(asset.cards, asset.strand_card, asset.uvd).reshape(-1, 3)[real]
    offsets = np.zeros(asset.n_strands + 1, np.int64)
    np.cumsum(asset.counts, out=offsets[1:])
    colors = None if asset.source_color is None else asset.source_color.reshape(-1, 3)[real]
    return Strands(np.ascontiguousarray(points, np.float32), offsets, colors, None, asset.meters_per_unit,
                   asset.up_axis, asset.root_uv)


def decode_gaussians(asset: HairAsset, sh_out: np.ndarray | None = None) -> Gaussians:
    """The Gaussians of every strand's own segments (``asset.n_gaussians``), strand-major then segment
    order, with SH from the MLP (written into ``sh_out`` where given: see :func:`strand_sh`; a strand
    of ``n`` points takes the first ``n - 1`` SH sets of its MLP output, spec 6.3)."""
    padded = asset.n_strands * (asset.points_per_strand - 1)
    sh = strand_sh(asset, sh_out).reshape(padded, asset.appearance.sh_coeffs, 3)
    if asset.variable:
        sh = sh[asset.real_segments().ravel()]
    return Gaussians(*gaussian_frames(asset), sh)


def gaussian_frames(asset: HairAsset) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The means, rotations, scales and opacities of :func:`decode_gaussians`, without the SH."""
    points = strand_points(asset.cards, asset.strand_card, asset.uvd)
    means, rotations, scales = segment_frames(points, asset.thickness)
    opacities = asset.opacity.reshape(-1).astype(np.float32)
    if asset.variable:
        real = asset.real_segments().ravel()
        means, rotations, scales, opacities = (a[real] for a in (means, rotations, scales, opacities))
    return means, rotations, scales, opacities


def sh_polynomial(sh, dirs):
    """``sum_lm c_lm Y_lm(dir)`` per channel, for SH ``[G, (deg+1)^2, 3]`` and unit directions
    ``[G, 3]``; only arithmetic and indexing, so numpy arrays and torch tensors both work."""
    deg = int(round(np.sqrt(sh.shape[1]))) - 1
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
    return res


def eval_sh(sh: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """RGB ``[G, 3]`` = ``max(0, sum_lm c_lm Y_lm(dir) + 0.5)``, the 3DGS (INRIA) convention.

    ``sh`` is ``[G, (deg+1)^2, 3]``; ``dirs`` ``[G, 3]`` unit view directions (camera to Gaussian).
    """
    return np.maximum(sh_polynomial(sh, dirs) + 0.5, 0.0)


def rgb_to_sh0(rgb: np.ndarray) -> np.ndarray:
    """The band-0 coefficient that renders as ``rgb`` (the inverse of the DC part of :func:`eval_sh`)."""
    return (np.asarray(rgb) - 0.5) / SH_C0
