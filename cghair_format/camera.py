"""Pinhole cameras shared by the renderers (training splatter, viewer, dataset tools).

Convention (OpenCV): camera x right, y down, z forward (view direction); pixel ``(i, j)`` covers
``[i, i+1) x [j, j+1)`` and its centre is ``(i + 0.5, j + 0.5)``; a camera point ``(x, y, z)``
projects to ``(fx x / z + cx, fy y / z + cy)``. NeRF-synthetic ``transforms.json`` stores
camera-to-world matrices in the OpenGL/Blender convention (y up, z backward); :meth:`Camera.from_nerf`
and :meth:`Camera.nerf_matrix` convert.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_FLIP_YZ = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass
class Camera:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    world_to_camera: np.ndarray  # [4, 4] float64, OpenCV convention

    @property
    def camera_to_world(self) -> np.ndarray:
        return np.linalg.inv(self.world_to_camera)

    @property
    def center(self) -> np.ndarray:
        return self.camera_to_world[:3, 3]

    @property
    def fov_x(self) -> float:
        return 2 * math.atan(self.width / (2 * self.fx))

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates ``[N, 2]`` and camera depths ``[N]`` of world points ``[N, 3]``."""
        pc = points @ self.world_to_camera[:3, :3].T + self.world_to_camera[:3, 3]
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack([self.fx * pc[:, 0] / z + self.cx, self.fy * pc[:, 1] / z + self.cy], axis=1)
        return uv, z

    @classmethod
    def look_at(cls, eye, target, up, width: int, height: int, fov_y_deg: float = 40.0) -> Camera:
        """A camera at ``eye`` looking at ``target`` with ``up`` pointing up in the image."""
        eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
        fwd = target - eye
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, up)
        if np.linalg.norm(right) < 1e-9:  # looking along up: pick any perpendicular
            right = np.cross(fwd, [1.0, 0.0, 0.0] if abs(fwd[0]) < 0.9 else [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        r = np.stack([right, down, fwd])  # rows: camera axes in world coordinates
        w2c = np.eye(4)
        w2c[:3, :3] = r
        w2c[:3, 3] = -r @ eye
        f = height / (2 * math.tan(math.radians(fov_y_deg) / 2))
        return cls(width, height, f, f, width / 2, height / 2, w2c)

    @classmethod
    def orbit(cls, target, distance: float, azimuth_deg: float, elevation_deg: float, width: int,
              height: int, up_axis: str = "Y", fov_y_deg: float = 40.0) -> Camera:
        """A camera on a sphere around ``target``: azimuth about the up axis, elevation above the
        horizontal plane (degrees); azimuth 0 looks from +Z (Y-up) or from -Y (Z-up) at the target."""
        az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
        horiz, height_dir = math.cos(el), math.sin(el)
        if up_axis == "Y":
            offset = np.array([horiz * math.sin(az), height_dir, horiz * math.cos(az)])
            up = np.array([0.0, 1.0, 0.0])
        else:
            offset = np.array([horiz * math.sin(az), -horiz * math.cos(az), height_dir])
            up = np.array([0.0, 0.0, 1.0])
        target = np.asarray(target, np.float64)
        return cls.look_at(target + distance * offset, target, up, width, height, fov_y_deg)

    @classmethod
    def from_nerf(cls, transform_matrix, camera_angle_x: float, width: int, height: int) -> Camera:
        """From a NeRF-synthetic frame: OpenGL camera-to-world matrix and horizontal field of view."""
        c2w = np.asarray(transform_matrix, np.float64) @ _FLIP_YZ
        f = width / (2 * math.tan(camera_angle_x / 2))
        return cls(width, height, f, f, width / 2, height / 2, np.linalg.inv(c2w))

    def nerf_matrix(self) -> np.ndarray:
        """The OpenGL/Blender camera-to-world matrix that NeRF-synthetic ``transforms.json`` stores."""
        return self.camera_to_world @ _FLIP_YZ
