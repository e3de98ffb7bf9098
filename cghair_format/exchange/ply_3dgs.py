"""3D Gaussian Splatting PLY (the INRIA layout every splat viewer opens).

One ``vertex`` element of float properties: ``x y z``, ``nx ny nz`` (zeros), ``f_dc_0..2`` (SH
band 0 per RGB channel), ``f_rest_*`` (the higher bands, channel-major: all R coefficients,
then G, then B; 45 for degree 3), ``opacity`` as a logit, ``scale_0..2`` as natural logs of the
standard deviations, ``rot_0..3`` the quaternion (w, x, y, z).

Orientation: 3DGS viewers (SuperSplat, the INRIA viewer, splat-transform) take the COLMAP
camera convention, y down, so our y-up hair is written turned 180 degrees about x by default
(``up="-y"``); ``"y"`` and ``"z"`` write it y-up or z-up. Means, rotations and SH coefficients
turn together. The header's comments say which up axis, the units and the anti-aliasing
convention (a 0.3 px^2 screen-space dilation, as in 3DGS; viewers that blur more dim thin hair).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..gaussians import Gaussians, sh_polynomial
from ._common import FLOAT32_MAX, StrandFileError, UnsupportedFormatError, check_scale
from ._ply import read_ply, write_ply

OPACITY_EPS = 1e-6  # opacities are clipped to [eps, 1 - eps] so their logit is finite
MIN_SCALE = 1e-12  # zero scales (zero-length segments) are written as log(MIN_SCALE)
REST_COUNTS = {0: 0, 9: 1, 24: 2, 45: 3}
LOG_SCALES = (-87.0, 88.0)  # the log standard deviations whose exponentials are normal float32s
UP_CHOICES = ("-y", "y", "z")
DEFAULT_UP = "-y"  # the INRIA / COLMAP convention 3DGS viewers expect
# rotations taking a y-up frame to each written up axis (column vectors: x' = R x)
FROM_Y_UP = {"y": np.eye(3), "-y": np.diag([1.0, -1.0, -1.0]),
             "z": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])}
TO_Y_UP = {"Y": np.eye(3), "Z": FROM_Y_UP["z"].T}
UP_COMMENT = "up "
AA_COMMENT = ("anti-aliasing: rendered by cghair with a 0.3 px^2 screen-space dilation (3DGS); "
              "set a viewer's blur to 0.3 (Spark's default blur dims thin hair ~3x)")


def orientation(source_up: str, up: str) -> np.ndarray:
    """The rotation from a ``source_up`` ("Y"/"Z") frame to the written ``up`` ("-y", "y", "z")."""
    if up not in FROM_Y_UP:
        raise UnsupportedFormatError(f"3DGS PLY up axis must be one of {', '.join(UP_CHOICES)}, got {up!r}")
    return FROM_Y_UP[up] @ TO_Y_UP[source_up.upper()]


def _quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix (one of the axis turns above)."""
    w = np.sqrt(max(0.0, 1 + np.trace(r))) / 2
    if w > 1e-6:
        v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (4 * w)
        return np.array([w, *v])
    axis = int(np.argmax(np.diag(r)))  # a half turn about a coordinate axis
    q = np.zeros(4)
    q[1 + axis] = 1.0
    return q


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = (b[:, i] for i in range(4))
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], 1)


def sh_rotation(r: np.ndarray, degree: int) -> np.ndarray:
    """``[K, K]`` matrix ``M`` with ``sh_rotated = M @ sh`` (per channel), for SH of ``degree``:
    the rotated function at ``d`` is the original at ``R^T d``. Fitted by least squares on 256
    directions, exact to float rounding (each band is closed under rotation); entries within 1e-9
    of an integer are snapped to it, so a half turn only flips signs."""
    k = (degree + 1) ** 2
    rng = np.random.default_rng(0)
    d = rng.normal(size=(256, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)

    def basis(dirs):  # [N, K]: every basis function at every direction
        unit = np.zeros((len(dirs), k, 1))
        cols = []
        for j in range(k):
            unit[:] = 0
            unit[:, j] = 1
            cols.append(sh_polynomial(unit, dirs)[:, 0])
        return np.stack(cols, 1)

    m = np.linalg.lstsq(basis(d), basis(d @ r), rcond=None)[0]
    return np.where(np.abs(m - np.round(m)) < 1e-9, np.round(m), m)  # exact 0 and +-1 (a half turn: signs)


def orient_gaussians(g: Gaussians, r: np.ndarray, scale: float = 1.0) -> Gaussians:
    """``g`` turned by the rotation ``r`` and scaled by ``scale`` (means and standard deviations)."""
    if np.allclose(r, np.eye(3)) and scale == 1.0:
        return g
    q = _quat_mul(_quat(r), g.rotations.astype(np.float64))
    k = g.sh.shape[1]
    m = sh_rotation(r, g.sh_degree).astype(np.float32)
    if np.array_equal(m, np.diag(np.diag(m))):  # a half turn: signs only
        sh = g.sh * np.diag(m)[None, :, None]
    else:  # one matrix product over all Gaussians and channels
        sh = (m @ g.sh.transpose(1, 0, 2).reshape(k, -1)).reshape(k, g.count, 3).transpose(1, 0, 2)
    return Gaussians(means=(g.means.astype(np.float64) @ r.T * scale).astype(np.float32),
                     rotations=q.astype(np.float32), scales=(g.scales * np.float32(scale)).astype(np.float32),
                     opacities=g.opacities, sh=sh.astype(np.float32))


def _check_values(path: str | Path, d: dict[str, np.ndarray]) -> None:
    """Refuse, naming the property, a value that is NaN, infinite or beyond float32, a log-scale whose
    exponential is not a normal float32 (``LOG_SCALES``) and a rotation quaternion of length zero."""
    for name, values in d.items():
        fits = np.abs(values) <= FLOAT32_MAX  # False for NaN and infinities too
        if not fits.all():
            raise StrandFileError(path, f"vertex property {name!r}: {np.count_nonzero(~fits)} values are NaN, "
                                        f"infinite or beyond float32 (the first at vertex {int(np.argmin(fits))})")
    for i in range(3):
        out = (d[f"scale_{i}"] < LOG_SCALES[0]) | (d[f"scale_{i}"] > LOG_SCALES[1])
        if out.any():
            raise StrandFileError(path, f"vertex property 'scale_{i}' (a log standard deviation) must lie in "
                                        f"{list(LOG_SCALES)}: {np.count_nonzero(out)} values do not (the first "
                                        f"at vertex {int(np.argmax(out))} is {d[f'scale_{i}'][np.argmax(out)]:g})")
    zero = ~(np.linalg.norm(np.stack([d[f"rot_{i}"] for i in range(4)], 1), axis=1) > 0)  # tiny ones underflow
    if zero.any():
        raise StrandFileError(path, f"vertex properties rot_0..3: {np.count_nonzero(zero)} rotations are zero "
                                    f"quaternions (the first at vertex {int(np.argmax(zero))})")


def write_3dgs_ply(gaussians: Gaussians, path: str | Path, pad_to_degree: int = 3, *, source_up: str = "Y",
                   up: str = DEFAULT_UP, scale: float = 1.0, meters_per_unit: float | None = None) -> None:
    """Write ``gaussians`` (in a ``source_up`` frame of ``meters_per_unit``) turned to ``up`` and
    multiplied by ``scale``; SH bands missing up to ``pad_to_degree`` are written as zeros
    (viewers commonly expect the 45 ``f_rest`` of degree 3). The units comment is written where
    ``meters_per_unit`` is known."""
    scale = check_scale(scale)
    g = orient_gaussians(gaussians, orientation(source_up, up), scale)
    deg = max(g.sh_degree, pad_to_degree)
    k = (deg + 1) ** 2
    sh = np.zeros((g.count, k, 3), np.float32)
    sh[:, :g.sh.shape[1]] = g.sh
    cols: dict[str, np.ndarray] = {}
    f32 = np.float32
    for i, axis in enumerate("xyz"):
        cols[axis] = g.means[:, i].astype(f32)
    for name in ("nx", "ny", "nz"):
        cols[name] = np.zeros(g.count, f32)
    for c in range(3):
        cols[f"f_dc_{c}"] = sh[:, 0, c]
    rest = sh[:, 1:, :].transpose(0, 2, 1).reshape(g.count, -1)  # channel-major
    for j in range(rest.shape[1]):
        cols[f"f_rest_{j}"] = rest[:, j]
    o = np.clip(g.opacities.astype(np.float64), OPACITY_EPS, 1 - OPACITY_EPS)
    cols["opacity"] = np.log(o / (1 - o)).astype(f32)
    for i in range(3):
        cols[f"scale_{i}"] = np.log(np.maximum(g.scales[:, i].astype(np.float64), MIN_SCALE)).astype(f32)
    for i in range(4):
        cols[f"rot_{i}"] = g.rotations[:, i].astype(f32)
    comments = ["3D Gaussian splats written by cghair", f"{UP_COMMENT}{up}",
                *([f"units {meters_per_unit / scale:g} m"] if meters_per_unit else []), AA_COMMENT]
    write_ply(path, [("vertex", cols)], comments=comments)


def read_3dgs_ply(path: str | Path, up: str | None = None) -> Gaussians:
    """Read a 3DGS PLY back: sigmoid opacities, exp scales, normalized (w, x, y, z) rotations.

    With ``up`` ("Y" or "Z") the Gaussians are turned from the file's up axis (its ``up``
    comment where cghair wrote one, else the INRIA convention, y down) into that frame."""
    ply = read_ply(path)
    v = ply.elements.get("vertex")
    need = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", *(f"scale_{i}" for i in range(3)),
            *(f"rot_{i}" for i in range(4))]
    if v is None or any(n not in v.data for n in need):
        missing = need if v is None else [n for n in need if n not in v.data]
        raise StrandFileError(path, f"not a 3DGS PLY: missing vertex properties {missing}")
    d = {k: np.asarray(a, np.float64) for k, a in v.data.items() if k in need or k.startswith("f_rest_")}
    _check_values(path, d)
    n_rest = sum(1 for k in d if k.startswith("f_rest_"))
    if n_rest not in REST_COUNTS:
        raise StrandFileError(path, f"3DGS PLY has {n_rest} f_rest properties; expected 0, 9, 24 or 45")
    deg = REST_COUNTS[n_rest]
    k = (deg + 1) ** 2
    g_count = len(d["x"])
    sh = np.zeros((g_count, k, 3))
    sh[:, 0] = np.stack([d[f"f_dc_{c}"] for c in range(3)], 1)
    if n_rest:
        rest = np.stack([d[f"f_rest_{j}"] for j in range(n_rest)], 1).reshape(g_count, 3, k - 1)
        sh[:, 1:] = rest.transpose(0, 2, 1)
    q = np.stack([d[f"rot_{i}"] for i in range(4)], 1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)  # _check_values refused zero quaternions
    means = np.stack([d["x"], d["y"], d["z"]], 1)
    g = Gaussians(means=means.astype(np.float32), rotations=q.astype(np.float32),
                  scales=np.exp(np.stack([d[f"scale_{i}"] for i in range(3)], 1)).astype(np.float32),
                  opacities=(0.5 + 0.5 * np.tanh(d["opacity"] / 2)).astype(np.float32),  # sigmoid, never overflows
                  sh=sh.astype(np.float32))
    if up is None:
        return g
    stated = [c[len(UP_COMMENT):].strip() for c in ply.comments if c.startswith(UP_COMMENT)]
    file_up = stated[0] if stated and stated[0] in FROM_Y_UP else DEFAULT_UP
    return orient_gaussians(g, orientation(up, file_up).T)
