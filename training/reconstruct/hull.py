"""The hair volume from the masks (a visual hull on a voxel grid) and a 3D orientation field on it,
triangulated from the views' 2D orientation maps.

A voxel is hair when it projects into the mask of every view that sees it. Each view's 2D
orientation at a voxel's projection says the strand lies in the plane through the camera centre
and that image line; the direction ``d`` minimising ``sum_v w_v (n_v . d)^2`` over the plane
normals ``n_v`` (weights: the 2D confidences) is the smallest eigenvector of the views' summed
``n n^T``. The field stores ``c d d^T`` per voxel (``c`` = how much the smallest eigenvalue stands
apart), which interpolates smoothly and has no sign, as strands have none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cghair_format.camera import Camera
from cghair_format.errors import CghError

from .orientation import OrientationMap

MASK_DILATION = 1  # pixels: a voxel whose projection misses the mask by this much is still kept
MASK_CLOSING = 3  # pixels: gaps between strands up to about twice this are closed
COARSE_RES = 48  # voxels along the side of the first, loose grid
MIN_FIELD_CONFIDENCE = 0.05  # 2D confidence below which a view says nothing at a voxel


class ReconstructError(CghError, ValueError):
    """Input the reconstruction cannot use (no masks, cameras that miss the hair, a bad scalp)."""


@dataclass
class Grid:
    origin: np.ndarray  # [3] world position of voxel (0, 0, 0)'s centre
    voxel: float  # edge length
    shape: tuple[int, int, int]

    def centres(self) -> np.ndarray:
        idx = np.stack(np.meshgrid(*[np.arange(n) for n in self.shape], indexing="ij"), -1).reshape(-1, 3)
        return self.origin + idx * self.voxel

    def to_index(self, points: np.ndarray) -> np.ndarray:
        """Continuous voxel coordinates of world points."""
        return (points - self.origin) / self.voxel


@dataclass
class Hull:
    grid: Grid
    occupancy: np.ndarray  # [X, Y, Z] bool
    field: np.ndarray | None = None  # [X, Y, Z, 3, 3] float32, c d d^T

    @property
    def points(self) -> np.ndarray:
        return self.grid.centres()[self.occupancy.ravel()]


def _masks(views) -> list[np.ndarray]:
    """Hair masks closed over the gaps between strands (a sparse render's gaps would carve tunnels
    through the hull), then dilated by ``MASK_DILATION``."""
    from scipy.ndimage import binary_closing, binary_dilation, binary_fill_holes

    out = []
    for v in views:
        m = binary_closing(v.image[..., 3] > 0.5, iterations=MASK_CLOSING, border_value=0)
        out.append(binary_dilation(binary_fill_holes(m), iterations=MASK_DILATION))
    return out


def check_masks(views) -> None:
    """Refuse views without a usable hair mask before any long work."""
    for v in views:
        a = v.image[..., 3] > 0.5
        if not a.any():
            raise ReconstructError(f"view {v.name}: its hair mask is empty (the camera does not see the hair)")
        if a.all():
            raise ReconstructError(f"view {v.name}: no hair mask (alpha or masks/ covers the whole image); "
                                   "reconstruction needs RGBA images or a masks folder")


def scene_bounds(cameras: list[Camera]) -> tuple[np.ndarray, float]:
    """Centre (the point nearest all optical axes) and a radius every view frames."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    half = []
    for cam in cameras:
        c2w = cam.camera_to_world
        axis = c2w[:3, 2] / np.linalg.norm(c2w[:3, 2])
        p = np.eye(3) - np.outer(axis, axis)
        a += p
        b += p @ cam.center
    centre = np.linalg.lstsq(a, b, rcond=None)[0]
    for cam in cameras:
        dist = np.linalg.norm(cam.center - centre)
        half.append(dist * min(cam.width / (2 * cam.fx), cam.height / (2 * cam.fy)))
    return centre, float(max(half))


def _carve(grid: Grid, views, masks) -> np.ndarray:
    pts = grid.centres()
    keep = np.ones(len(pts), bool)
    for v, m in zip(views, masks, strict=True):
        uv, z = v.camera.project(pts)
        h, w = m.shape
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        px = np.clip(uv[:, 0].astype(int), 0, w - 1)
        py = np.clip(uv[:, 1].astype(int), 0, h - 1)
        keep &= ~inside | m[py, px]  # a view that does not see a voxel does not carve it
    return keep.reshape(grid.shape)


def visual_hull(views, resolution: int = 96) -> Hull:
    """Carve a loose cube around what all cameras frame, then a grid of ``resolution`` voxels along
    the longest side of the first hull's bounding box."""
    check_masks(views)
    masks = _masks(views)
    centre, radius = scene_bounds([v.camera for v in views])
    vox = 2 * radius / COARSE_RES
    coarse = Grid(centre - radius + vox / 2, vox, (COARSE_RES,) * 3)
    occ = _carve(coarse, views, masks)
    if not occ.any():
        raise ReconstructError("the views' hair masks have no common volume: the cameras do not see the same "
                               "hair (check the camera poses)")
    idx = np.argwhere(occ)
    lo = coarse.origin + (idx.min(0) - 1) * vox
    hi = coarse.origin + (idx.max(0) + 1) * vox
    fine_vox = float((hi - lo).max() / resolution)
    shape = tuple(int(n) for n in np.ceil((hi - lo) / fine_vox).astype(int) + 1)
    grid = Grid(lo, fine_vox, shape)
    from scipy.ndimage import binary_fill_holes

    return Hull(grid, binary_fill_holes(_carve(grid, views, masks)))


def pixel_footprint(hull: Hull, views) -> float:
    """Mean width in world units of one pixel at the hull's centroid, over the views."""
    c = hull.grid.origin + np.argwhere(hull.occupancy).mean(0) * hull.grid.voxel
    return float(np.mean([np.linalg.norm(v.camera.center - c) / v.camera.fx for v in views]))


def _line_plane_normals(cam: Camera, uv: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """World normals of the planes through the camera centre and the image lines (point, angle)."""
    c2w = cam.camera_to_world[:3, :3]

    def ray(p):
        d = np.stack([(p[:, 0] - cam.cx) / cam.fx, (p[:, 1] - cam.cy) / cam.fy, np.ones(len(p))], 1)
        return d @ c2w.T

    t = np.stack([np.cos(angle), np.sin(angle)], 1)
    n = np.cross(ray(uv), ray(uv + t))
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def orientation_field(hull: Hull, views, maps: list[OrientationMap]) -> Hull:
    """Fill ``hull.field`` from the views' orientation maps (see the module docstring)."""
    occ = hull.occupancy.ravel()
    pts = hull.grid.centres()[occ]
    acc = np.zeros((len(pts), 3, 3))
    for v, m in zip(views, maps, strict=True):
        uv, z = v.camera.project(pts)
        h, w = m.angle.shape
        px, py = uv[:, 0].astype(int), uv[:, 1].astype(int)
        ok = (z > 0) & (px >= 0) & (px < w) & (py >= 0) & (py < h)
        px, py = np.clip(px, 0, w - 1), np.clip(py, 0, h - 1)
        conf = np.where(ok, m.confidence[py, px], 0.0)
        sel = conf > MIN_FIELD_CONFIDENCE
        n = _line_plane_normals(v.camera, uv[sel], m.angle[py[sel], px[sel]])
        acc[sel] += conf[sel, None, None] * n[:, :, None] * n[:, None, :]
    evals, evecs = np.linalg.eigh(acc)  # ascending
    d = evecs[:, :, 0]
    c = np.where(evals[:, 1] > 1e-9, (evals[:, 1] - evals[:, 0]) / np.maximum(evals[:, 1], 1e-9), 0.0)
    field = np.zeros((occ.size, 3, 3), np.float32)
    field[occ] = c[:, None, None] * d[:, :, None] * d[:, None, :]
    hull.field = field.reshape(*hull.grid.shape, 3, 3)
    return hull


def trilinear(volume: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Sample ``volume [X, Y, Z, ...]`` at continuous voxel coordinates ``[N, 3]`` (zero outside)."""
    shape = np.array(volume.shape[:3])
    base = np.floor(coords).astype(int)
    frac = coords - base
    out = np.zeros((len(coords), *volume.shape[3:]), np.float64)
    for corner in range(8):
        off = np.array([(corner >> k) & 1 for k in range(3)])
        idx = base + off
        w = np.prod(np.where(off, frac, 1 - frac), axis=1)
        ok = ((idx >= 0) & (idx < shape)).all(1)
        ci = np.clip(idx, 0, shape - 1)
        val = volume[ci[:, 0], ci[:, 1], ci[:, 2]]
        out += (w * ok).reshape(-1, *([1] * (val.ndim - 1))) * val
    return out
