"""A reader of COLMAP sparse models (cameras and registered images), binary or text.

Written from COLMAP's documented output format (https://colmap.github.io/format.html). All values
are little-endian. Only what training needs is read: ``points3D`` is not.

``cameras.bin``: ``uint64`` count, then per camera ``int32 camera_id, int32 model_id,
uint64 width, uint64 height, float64 params[n]`` (``n`` fixed by the model).
``images.bin``: ``uint64`` count, then per image ``uint32 image_id, float64 qw qx qy qz,
float64 tx ty tz, uint32 camera_id``, the name as a NUL-terminated string, ``uint64`` point count
and that many ``float64 x, float64 y, int64 point3D_id``.
``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS...`` per line; ``images.txt``: two lines per
image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` and its (possibly empty) 2D points. Lines
starting with ``#`` are comments.

Poses are world-to-camera (``x_cam = R(q) x_world + t``) in COLMAP's camera frame, which is
OpenCV's (x right, y down, z forward), and the centre of the top-left pixel is (0.5, 0.5): the
same conventions as :class:`cghair_format.camera.Camera`, so intrinsics and poses carry over as they
are.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cghair_format.camera import Camera
from cghair_format.errors import CghError

# COLMAP's camera model ids and names (colmap/src/colmap/sensor/models.h)
MODEL_NAMES = {0: "SIMPLE_PINHOLE", 1: "PINHOLE", 2: "SIMPLE_RADIAL", 3: "RADIAL", 4: "OPENCV",
               5: "OPENCV_FISHEYE", 6: "FULL_OPENCV", 7: "FOV", 8: "SIMPLE_RADIAL_FISHEYE",
               9: "RADIAL_FISHEYE", 10: "THIN_PRISM_FISHEYE", 11: "RAD_TAN_THIN_PRISM_FISHEYE"}
PINHOLE_PARAMS = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4}  # f cx cy | fx fy cx cy
MODEL_FILES = ("cameras", "images")
UNDISTORT_HINT = ("undistort the capture first: colmap image_undistorter --image_path IMAGES "
                  "--input_path SPARSE --output_path OUT (it writes PINHOLE cameras and undistorted images)")


class ColmapError(CghError, ValueError):
    """A COLMAP model is malformed, or uses a camera model that training does not support."""


@dataclass
class ColmapImage:
    name: str  # path relative to the images folder
    camera: Camera  # intrinsics at the model's width x height


def find_model(folder: str | Path) -> tuple[Path, str] | None:
    """The model in ``folder`` as ``(folder, "bin" | "txt")``, or None when it holds none."""
    folder = Path(folder)
    for ext in ("bin", "txt"):
        if all((folder / f"{name}.{ext}").is_file() for name in MODEL_FILES):
            return folder, ext
    return None


def read_model(folder: str | Path) -> list[ColmapImage]:
    """The registered images of the model in ``folder`` (binary preferred), sorted by name."""
    found = find_model(folder)
    if found is None:
        raise ColmapError(f"{folder}: no COLMAP model (cameras and images, .bin or .txt)")
    folder, ext = found
    if ext == "bin":
        cameras = _read_cameras_bin(folder / "cameras.bin")
        images = _read_images_bin(folder / "images.bin")
    else:
        cameras = _read_cameras_txt(folder / "cameras.txt")
        images = _read_images_txt(folder / "images.txt")
    if not images:
        raise ColmapError(f"{folder}: the COLMAP model has no registered images")
    out = []
    for name, camera_id, qvec, tvec in images:
        if camera_id not in cameras:
            raise ColmapError(f"{folder}: image {name!r} refers to camera {camera_id}, which is not in the model")
        width, height, fx, fy, cx, cy = cameras[camera_id]
        w2c = np.eye(4)
        w2c[:3, :3] = quaternion_matrix(qvec)
        w2c[:3, 3] = tvec
        if not np.isfinite(w2c).all():
            raise ColmapError(f"{folder}: image {name!r} has a non-finite or zero rotation or translation")
        out.append(ColmapImage(name, Camera(width, height, fx, fy, cx, cy, w2c)))
    return sorted(out, key=lambda im: im.name)


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrix of the (w, x, y, z) quaternion ``q`` (normalised first)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _intrinsics(path: Path, camera_id: int, model: str, width: int, height: int, params) -> tuple:
    if model not in PINHOLE_PARAMS:
        raise ColmapError(f"{path}: camera {camera_id} uses the {model} model, which needs undistortion; "
                          f"training reads SIMPLE_PINHOLE and PINHOLE cameras only: {UNDISTORT_HINT}")
    if len(params) != PINHOLE_PARAMS[model]:
        raise ColmapError(f"{path}: camera {camera_id} ({model}) has {len(params)} parameters, "
                          f"expected {PINHOLE_PARAMS[model]}")
    if width < 1 or height < 1 or not np.isfinite(params).all() or min(params[0], params[-3]) <= 0:
        raise ColmapError(f"{path}: camera {camera_id} has a bad size or focal length")
    if model == "SIMPLE_PINHOLE":
        f, cx, cy = params
        return int(width), int(height), float(f), float(f), float(cx), float(cy)
    fx, fy, cx, cy = params
    return int(width), int(height), float(fx), float(fy), float(cx), float(cy)


class _Reader:
    """Bounds-checked little-endian reads from a file's bytes."""

    def __init__(self, path: Path):
        self.path, self.data, self.pos = path, path.read_bytes(), 0

    def take(self, fmt: str) -> tuple:
        size = struct.calcsize(fmt)
        if self.pos + size > len(self.data):
            raise ColmapError(f"{self.path}: truncated at byte {self.pos} (COLMAP binary model)")
        out = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += size
        return out

    def skip(self, size: int) -> None:
        if size < 0 or self.pos + size > len(self.data):
            raise ColmapError(f"{self.path}: truncated at byte {self.pos} (COLMAP binary model)")
        self.pos += size

    def name(self) -> str:
        end = self.data.find(b"\0", self.pos)
        if end < 0:
            raise ColmapError(f"{self.path}: unterminated image name at byte {self.pos}")
        raw, self.pos = self.data[self.pos:end], end + 1
        return raw.decode("utf-8", errors="replace")


def _read_cameras_bin(path: Path) -> dict[int, tuple]:
    r = _Reader(path)
    (count,) = r.take("<Q")
    cameras = {}
    for _ in range(count):
        camera_id, model_id, width, height = r.take("<iiQQ")
        model = MODEL_NAMES.get(model_id, f"unknown ({model_id})")
        if model not in PINHOLE_PARAMS:  # refuse before reading parameters of unknown length
            _intrinsics(path, camera_id, model, width, height, ())
        params = np.array(r.take(f"<{PINHOLE_PARAMS[model]}d"))
        cameras[camera_id] = _intrinsics(path, camera_id, model, width, height, params)
    return cameras


def _read_images_bin(path: Path) -> list[tuple]:
    r = _Reader(path)
    (count,) = r.take("<Q")
    images = []
    for _ in range(count):
        fields = r.take("<I7dI")
        name = r.name()
        (n_points,) = r.take("<Q")
        r.skip(24 * n_points)
        images.append((name, fields[8], fields[1:5], fields[5:8]))
    return images


def _data_lines(path: Path) -> list[str]:
    try:
        return path.read_text().splitlines()
    except UnicodeDecodeError as exc:
        raise ColmapError(f"{path}: not a text COLMAP model ({exc})") from exc


def _read_cameras_txt(path: Path) -> dict[int, tuple]:
    cameras = {}
    for number, line in enumerate(_data_lines(path), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        try:
            camera_id, model, width, height = int(parts[0]), parts[1], int(parts[2]), int(parts[3])
            params = np.array([float(p) for p in parts[4:]])
        except (IndexError, ValueError) as exc:
            raise ColmapError(f"{path}:{number}: malformed camera line ({exc})") from exc
        cameras[camera_id] = _intrinsics(path, camera_id, model, width, height, params)
    return cameras


def _read_images_txt(path: Path) -> list[tuple]:
    lines = _data_lines(path)
    images, i = [], 0
    while i < len(lines):
        parts = lines[i].split()
        if not parts or parts[0].startswith("#"):
            i += 1
            continue
        try:
            values = [float(p) for p in parts[1:8]]
            camera_id, name = int(parts[8]), " ".join(parts[9:])
        except (IndexError, ValueError) as exc:
            raise ColmapError(f"{path}:{i + 1}: malformed image line ({exc})") from exc
        if not name:
            raise ColmapError(f"{path}:{i + 1}: image line without a name")
        images.append((name, camera_id, values[:4], values[4:]))
        i += 2  # the next line holds the image's 2D points (possibly empty)
    return images
