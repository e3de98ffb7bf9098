"""The compiled CPU splatter: the image contract of spec/rendering.md, as the reference
:func:`training.splatter.render`, forward and backward in :mod:`training._raster` on every core.

Tile-based as the original 3DGS rasterizer: per Gaussian the EWA projection and the 16 x 16 tiles
its tight footprint (3-sigma square AND the ellipse where alpha can reach 1/255) touches; per tile
the Gaussians front to back (a stable depth sort, the reference's tie order); per pixel
front-to-back compositing with early termination at T < 1e-4, keeping only the final
transmittance and the last contribution, with SH colours evaluated only for the Gaussians that
contribute. The backward pass walks each pixel's contributions back to front from there,
recomputing alpha, so no (pixel, Gaussian) pair is ever stored, and skips the Gaussians that
received no gradient (most of them in dense hair).

Differentiable w.r.t. means, quats, scales, opacities and sh through rgb and alpha. The depth
output is forward-only (its gradient is not propagated), and the background is a constant. When
means, quats and scales need no gradient (frozen geometry) the projection's backward is skipped.
Threads: OpenMP's (``OMP_NUM_THREADS``, default every core). Work and gradient arrays are kept
and reused between calls (:func:`release_memory` drops them).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import torch
from torch import Tensor

from cghair_format.errors import CghError
from training.splatter import RenderOutput, check_shapes

if TYPE_CHECKING:
    from cghair_format.camera import Camera

try:
    from training import _raster
except ImportError:  # not built: render() says how to build it
    _raster = None

# Gaussians per pixel from which an SH function is asked for the contributing Gaussians only: the
# extra opacity-only compositing pays where most Gaussians are hidden (docs/training.md, "Around
# the rasterizer")
SHOWN_ONLY_PER_PIXEL = 16


ShSource = Callable[[Tensor | None], Tensor]  # Gaussian indices -> their SH [n, C, 3]; None: all


class Tiles(NamedTuple):
    """A frame's Gaussians per tile (``_raster.bin_tiles``), as the kernels read them."""

    feat: np.ndarray  # [G, _raster.NF] float32, _raster.project's
    tile_start: np.ndarray  # [tiles + 1] int32, the first entry of each tile
    entries: np.ndarray  # [entries] int32, the Gaussian of each, tile by tile, front to back
    tiles_x: int
    width: int
    height: int


class Shading(NamedTuple):
    """How ``_raster.rasterize`` colours a Gaussian: its SH seen from the camera."""

    means: np.ndarray  # [G, 3] float32
    sh: np.ndarray  # [rows, C, 3] float32
    sh_row: np.ndarray  # [G] int32 Gaussian -> row of sh; empty: row g
    cam: np.ndarray  # [19] float64, _camera_vector's
    bg: np.ndarray  # [3] float32


class Pixels(NamedTuple):
    """What ``_raster.rasterize`` writes: the image and what its backward pass needs."""

    rgb: np.ndarray  # [H, W, 3] float32
    alpha: np.ndarray  # [H, W] float32
    depth: np.ndarray  # [H, W] float32
    t_final: np.ndarray  # [H, W] float64, the transmittance left
    last: np.ndarray  # [H, W] int32, the last contribution within its tile's list, -1: none
    entry_colour: np.ndarray  # [entries, 3] float32


class PixelGrads(NamedTuple):
    """What ``_raster.rasterize_backward`` reads, and its output ``pair_grad``."""

    entry_pair: np.ndarray  # [entries] int32, the (Gaussian, tile) pair of each entry
    entry_colour: np.ndarray  # [entries, 3] float32, Pixels'
    bg: np.ndarray  # [3] float32
    grad_rgb: np.ndarray  # [H, W, 3] float32
    grad_alpha: np.ndarray  # [H, W] float32
    t_final: np.ndarray  # [H, W] float64, Pixels'
    last: np.ndarray  # [H, W] int32, Pixels'
    pair_grad: np.ndarray  # [pairs, 9] float32, written


class NativeSplatterMissing(CghError, ImportError):
    """The compiled splatting kernel (training/_raster.pyx) is not built."""


def available() -> bool:
    """Whether the compiled kernel is importable."""
    return _raster is not None


def _require() -> None:
    if _raster is None:
        raise NativeSplatterMissing("the native splatter's compiled kernel training/_raster is not built: run "
                                    "`make venv`, or `python setup.py build_ext --inplace` in the repository")


def _idle_refs() -> int:
    """What sys.getrefcount says, in the comprehension of _Pool.take, of an array only a list holds
    (measured: interpreters differ in the references they count)."""
    arrays = [np.empty(1)]
    return [sys.getrefcount(a) for a in arrays][0]


_IDLE_REFS = _idle_refs()


class _Pool:
    """Reused work and gradient arrays: writing a fresh array of hundreds of MB (the SH gradient of a
    large asset) costs more in page faults than the whole rasterization. An array is handed out again only once
    nothing but the pool refers to it (a torch tensor made with ``torch.from_numpy`` holds a
    reference to its array until the tensor's storage dies), so reuse never aliases live data."""

    KEEP = 32  # arrays kept per dtype
    SMALL = 1 << 18  # elements; smaller arrays are not worth keeping

    def __init__(self):
        self.free: dict[np.dtype, list[np.ndarray]] = {}

    def take(self, shape: tuple[int, ...], dtype) -> np.ndarray:
        size, arrays = int(np.prod(shape)), self.free.setdefault(np.dtype(dtype), [])
        if size < self.SMALL:
            return np.empty(shape, dtype)
        # the smallest idle array that fits: one referred to as often as an array only the pool holds
        fits = [a for a in arrays if a.size >= size and sys.getrefcount(a) == _IDLE_REFS]
        if fits:
            return min(fits, key=lambda a: a.size)[:size].reshape(shape)
        base = np.empty(size, dtype)
        if len(arrays) < self.KEEP:
            arrays.append(base)
        return base.reshape(shape)


_POOL = _Pool()


def release_memory() -> None:
    """Drop the reused arrays (for a large asset, about a GB per view kept alive at once)."""
    _POOL.free.clear()


def _camera_vector(camera: Camera) -> np.ndarray:
    """World-to-camera rotation (row-major) and translation, camera centre, fx, fy, cx, cy."""
    w2c = np.asarray(camera.world_to_camera, np.float64)
    return np.concatenate([w2c[:3, :3].ravel(), w2c[:3, 3], np.asarray(camera.center, np.float64),
                           [camera.fx, camera.fy, camera.cx, camera.cy]]).astype(np.float64)


def _f32(t: Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().to(torch.float32).numpy())


class _Frame:
    """What one forward pass leaves for its backward pass."""

    def __init__(self, geometry: list[np.ndarray], camera: Camera, background: np.ndarray):
        _require()
        means, quats, scales, opac = geometry
        self.geometry = geometry
        self.cam = _camera_vector(camera)
        self.width, self.height = int(camera.width), int(camera.height)
        self.background = background
        tile = _raster.TILE  # the tile side in pixels and the features kept per Gaussian: the kernel's
        self.tiles_x = (self.width + tile - 1) // tile
        tiles = self.tiles_x * ((self.height + tile - 1) // tile)
        g = means.shape[0]
        self.feat = _POOL.take((g, _raster.NF), np.float32)
        rect = _POOL.take((g, 4), np.int32)
        ntiles = _POOL.take((g,), np.int64)
        _raster.project(means, quats, scales, opac, self.cam, self.width, self.height, self.feat, rect, ntiles)
        pairs = int(ntiles.sum())
        self.pair_start = _POOL.take((g + 1,), np.int64)
        self.tile_start = np.empty(tiles + 1, np.int32)
        self.entries = _POOL.take((pairs,), np.int32)
        self.entry_pair = _POOL.take((pairs,), np.int32)
        self.visible = _raster.bin_tiles(self.feat, rect, ntiles, self.tiles_x, tiles // self.tiles_x,
                                         self.pair_start, self.tile_start, self.entries, self.entry_pair)
        self.tiles = Tiles(self.feat, self.tile_start, self.entries, self.tiles_x, self.width, self.height)
        self.sh, self.sh_row = None, np.empty(0, np.int32)

    def contributors(self) -> np.ndarray:
        """Indices of the Gaussians that :meth:`rasterize` takes a colour from, ascending."""
        flags = np.zeros(len(self.geometry[0]), np.uint8)
        _raster.contributors(self.tiles, flags)
        return np.flatnonzero(flags)

    def rasterize(self, sh: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The image; Gaussian g's SH are ``sh[rows[g]]`` (``sh[g]`` without ``rows``)."""
        h, w = self.height, self.width
        self.sh = sh
        if rows is not None:
            self.sh_row = rows
        self.pixels = Pixels(np.empty((h, w, 3), np.float32), np.empty((h, w), np.float32),
                             np.empty((h, w), np.float32), np.empty((h, w), np.float64), np.empty((h, w), np.int32),
                             _POOL.take((len(self.entries), 3), np.float32))
        _raster.rasterize(self.tiles, Shading(self.geometry[0], sh, self.sh_row, self.cam, self.background),
                          self.pixels)
        return self.pixels.rgb, self.pixels.alpha, self.pixels.depth

    def backward(self, grad_rgb: np.ndarray, grad_alpha: np.ndarray, geometry: bool = True) -> list[np.ndarray]:
        """Gradients of means, quats, scales, opacities and sh; without ``geometry`` the first three
        are not computed (and the arrays returned for them hold garbage)."""
        means, quats, scales, _ = self.geometry
        pair_grad = _POOL.take((len(self.entries), 9), np.float32)
        px = self.pixels
        _raster.rasterize_backward(self.tiles, PixelGrads(self.entry_pair, px.entry_colour, self.background, grad_rgb,
                                                          grad_alpha, px.t_final, px.last, pair_grad))
        grads = [_POOL.take(a.shape, np.float32) for a in (*self.geometry, self.sh)]
        _raster.project_backward(means, quats, scales, self.sh, self.sh_row, self.cam, self.pair_start, pair_grad,
                                 geometry, *grads)
        return grads


class _Render(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, quats, scales, opacities, sh, frame, rows):
        rgb, alpha, depth = frame.rasterize(_f32(sh), rows)
        ctx.frame = frame
        ctx.dtypes = [t.dtype for t in (means, quats, scales, opacities, sh)]
        ctx.mark_non_differentiable(depth_t := torch.from_numpy(depth).to(means.dtype))
        return torch.from_numpy(rgb).to(means.dtype), torch.from_numpy(alpha).to(means.dtype), depth_t

    @staticmethod
    def backward(ctx, grad_rgb, grad_alpha, _grad_depth):
        h, w = ctx.frame.height, ctx.frame.width
        grad_rgb = _f32(grad_rgb) if grad_rgb is not None else np.zeros((h, w, 3), np.float32)
        grad_alpha = _f32(grad_alpha) if grad_alpha is not None else np.zeros((h, w), np.float32)
        # frozen geometry (means, quats and scales not requiring grad): the projection's backward is skipped
        grads = ctx.frame.backward(grad_rgb, grad_alpha, geometry=any(ctx.needs_input_grad[:3]))
        ctx.frame = None
        return (*(torch.from_numpy(g).to(dt) if need else None
                  for g, dt, need in zip(grads, ctx.dtypes, ctx.needs_input_grad[:5], strict=True)), None, None)


def render(
    means: Tensor,  # [G, 3]
    quats: Tensor,  # [G, 4] (w, x, y, z), normalised inside
    scales: Tensor,  # [G, 3] standard deviations
    opacities: Tensor,  # [G] in [0, 1]
    sh: Tensor | ShSource,  # [G, C, 3], C = (deg+1)^2, or a function of Gaussian indices
    camera: Camera,
    background: tuple[float, float, float] | Tensor = (0.0, 0.0, 0.0),
) -> RenderOutput:
    """Render one camera as :func:`training.splatter.render` does (spec/rendering.md), on the CPU.

    ``sh`` may also be a function that returns the SH ``[n, C, 3]`` of the Gaussians at indices
    ``[n]`` (all of them for None): with at least :data:`SHOWN_ONLY_PER_PIXEL` Gaussians a pixel it
    is asked only for those that contribute to the image, which in dense hair are a small part
    (the image is the same), else for all.

    Computes in float32 (other float dtypes are converted, and so are their gradients). Gradients
    flow from rgb and alpha to every tensor argument; depth and the background get none.
    """
    _require()
    check_shapes(means, quats, scales, opacities, sh if isinstance(sh, Tensor) else None)
    if any(t.device.type != "cpu" for t in (means, quats, scales, opacities)):
        raise ValueError("the native splatter runs on the CPU: pass CPU tensors (use gsplat on CUDA)")
    bg = np.ascontiguousarray(torch.as_tensor(background).detach().reshape(3).to(torch.float32).numpy())
    frame = _Frame([_f32(t) for t in (means, quats, scales, opacities)], camera, bg)
    rows = None
    if not isinstance(sh, Tensor) and len(means) < SHOWN_ONLY_PER_PIXEL * frame.width * frame.height:
        sh = sh(None)
    if not isinstance(sh, Tensor):
        index = frame.contributors()
        rows = np.full(len(means), -1, np.int32)
        rows[index] = np.arange(len(index), dtype=np.int32)
        sh = sh(torch.from_numpy(index))
        if sh.ndim != 3 or sh.shape[0] != len(index) or sh.shape[1:] not in ((1, 3), (4, 3), (9, 3), (16, 3)):
            raise ValueError(f"the SH function gave {tuple(sh.shape)} for {len(index)} Gaussians; want [n, C, 3]")
    rgb, alpha, depth = _Render.apply(means, quats, scales, opacities, sh, frame, rows)
    return RenderOutput(rgb, alpha, depth)
