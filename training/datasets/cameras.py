"""The cameras of a rendered dataset: an orbit that frames the strands."""

from __future__ import annotations

import math

import numpy as np

from cghair_format.camera import Camera

FOV_Y_DEG = 40.0
FRAME_MARGIN = 1.15  # the bounding sphere fills the view with this much room
ELEVATION_RANGE = (-15.0, 55.0)


def bounding_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    lo, hi = points.min(0), points.max(0)
    centre = (lo + hi) / 2
    return centre.astype(np.float64), float(np.linalg.norm(points - centre, axis=1).max())


def orbit_cameras(points: np.ndarray, n: int, res: int, up_axis: str = "Y") -> list[Camera]:
    """``n`` cameras on a golden-angle spiral around the points' bounding sphere, all framing it."""
    centre, radius = bounding_sphere(points)
    distance = FRAME_MARGIN * max(radius, 1e-9) / math.sin(math.radians(FOV_Y_DEG) / 2)
    lo, hi = ELEVATION_RANGE
    cams = []
    for i in range(n):
        az = (i * 137.50776405) % 360.0
        el = lo + (hi - lo) * ((i + 0.5) / n)
        cams.append(Camera.orbit(centre, distance, az, el, res, res, up_axis=up_axis, fov_y_deg=FOV_Y_DEG))
    return cams
