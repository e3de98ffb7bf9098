"""Do the strands sit where the views see hair? Checked before training, so that strands in another
frame (scale, up axis, placement) are refused at once, not after hours."""

from __future__ import annotations

import numpy as np

from .types import DatasetError, View

MASK_LEVEL = 0.5  # a pixel is hair where its mask is at least this
# ... or, in masks of sub-pixel hair, where it is at least this: any coverage (Cycles at its default 16
# samples covers a pixel in steps of 1/16), above a soft mask's faint noise
COVERAGE_LEVEL = 0.05
# masks are of sub-pixel hair when fewer than this share of their covered pixels reach MASK_LEVEL (a
# Cycles render of 800 wavy strands at 128 px: 3 %; splat renders and real captures' masks: 90 % or more)
THIN_SHARE = 0.25
MIN_INSIDE = 0.5  # refuse training when fewer strand points than this fall inside the masks
CHECK_POINTS = 20_000  # strand points projected by the frame check


def fraction_in_masks(points: np.ndarray, views: list[View], max_points: int = CHECK_POINTS,
                      level: float = MASK_LEVEL) -> np.ndarray:
    """Per view, the fraction of ``points`` ``[N, 3]`` (an even subsample of at most ``max_points``)
    that project onto hair: in front of the camera, inside the image, on a pixel whose mask (dilated
    by one pixel, for thin strands) is at least ``level``."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    points = points[:: max(1, len(points) // max_points)]
    out = np.zeros(len(views))
    for k, view in enumerate(views):
        mask = view.image[..., 3] >= level
        grown = mask.copy()
        grown[1:] |= mask[:-1]
        grown[:-1] |= mask[1:]
        grown[:, 1:] |= grown[:, :-1].copy()
        grown[:, :-1] |= grown[:, 1:].copy()
        uv, z = view.camera.project(points)
        h, w = mask.shape
        ok = (z > 0) & np.isfinite(uv).all(1)
        ok &= (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        i = np.clip(np.floor(uv[ok, 0]).astype(np.int64), 0, w - 1)
        j = np.clip(np.floor(uv[ok, 1]).astype(np.int64), 0, h - 1)
        out[k] = grown[j, i].sum() / max(len(points), 1)
    return out


def solid_share(views: list[View]) -> tuple[float, float]:
    """The share of the views' pixels with any hair coverage (at least :data:`COVERAGE_LEVEL`), and the
    share of those that are hair at :data:`MASK_LEVEL`."""
    alpha = [v.image[..., 3] for v in views]
    covered = sum(int((a >= COVERAGE_LEVEL).sum()) for a in alpha)
    solid = sum(int((a >= MASK_LEVEL).sum()) for a in alpha)
    return covered / max(sum(a.size for a in alpha), 1), solid / max(covered, 1)


def check_strands_in_views(points: np.ndarray, views: list[View], min_inside: float = MIN_INSIDE) -> float:
    """Refuse strands that do not sit where the views see hair (another frame, scale or up axis);
    returns the fraction of strand points inside the masks over all views. Masks of sub-pixel hair,
    mostly translucent (:data:`THIN_SHARE`), count every covered pixel as hair."""
    covered, solid = solid_share(views)
    thin = solid < THIN_SHARE
    per_view = fraction_in_masks(points, views, level=COVERAGE_LEVEL if thin else MASK_LEVEL)
    inside = float(per_view.mean()) if len(per_view) else 0.0
    if inside >= min_inside:
        return inside
    worst = int(np.argmin(per_view))
    where = (f"only {inside:.0%} of the strand points project inside the views' hair masks (view "
             f"{views[worst].name}: {per_view[worst]:.0%})")
    frame = ("bring the strands into the capture's coordinates (scale, up axis, placement) before training")
    if not thin:
        raise DatasetError(f"{where}; the strands and cameras are not in the same frame: {frame}")
    raise DatasetError(
        f"{where}, counting every pixel with any coverage: the masks are thin ({covered:.0%} of the pixels "
        f"covered, {solid:.0%} of those more than half); if the strands are in the capture's frame, render "
        f"thicker or denser hair (render-dataset --thickness, --densify) or at a lower resolution; else the "
        f"strands and cameras are not in the same frame: {frame}")
