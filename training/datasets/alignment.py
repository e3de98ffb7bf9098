"""Do the strands sit where the views see hair? Checked before training, so that strands in another
frame (scale, up axis, placement) are refused at once, not after hours."""

from __future__ import annotations

import numpy as np

from .types import DatasetError, View

MASK_LEVEL = 0.5  # a pixel is hair where its mask is at least this
MIN_INSIDE = 0.5  # refuse training when fewer strand points than this fall inside the masks
CHECK_POINTS = 20_000  # strand points projected by the frame check


def fraction_in_masks(points: np.ndarray, views: list[View], max_points: int = CHECK_POINTS) -> np.ndarray:
    """Per view, the fraction of ``points`` ``[N, 3]`` (an even subsample of at most ``max_points``)
    that project onto hair: in front of the camera, inside the image, on a pixel whose mask (dilated
    by one pixel, for thin strands) is at least :data:`MASK_LEVEL`."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    points = points[:: max(1, len(points) // max_points)]
    out = np.zeros(len(views))
    for k, view in enumerate(views):
        mask = view.image[..., 3] >= MASK_LEVEL
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


def check_strands_in_views(points: np.ndarray, views: list[View], min_inside: float = MIN_INSIDE) -> float:
    """Refuse strands that do not sit where the views see hair (another frame, scale or up axis);
    returns the fraction of strand points inside the masks over all views."""
    per_view = fraction_in_masks(points, views)
    inside = float(per_view.mean()) if len(per_view) else 0.0
    if inside < min_inside:
        worst = int(np.argmin(per_view))
        raise DatasetError(
            f"only {inside:.0%} of the strand points project inside the views' hair masks (view {views[worst].name}: "
            f"{per_view[worst]:.0%}); the strands and cameras are not in the same frame: bring the strands "
            "into the capture's coordinates (scale, up axis, placement) before training")
    return inside
