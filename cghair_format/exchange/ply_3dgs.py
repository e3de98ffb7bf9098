"""3D Gaussian Splatting PLY (the INRIA layout every splat viewer opens).

One ``vertex`` element of float properties: ``x y z``, ``nx ny nz`` (zeros), ``f_dc_0..2`` (SH
band 0 per RGB channel), ``f_rest_*`` (the higher bands, channel-major: all R coefficients,
then G, then B; 45 for degree 3), ``opacity`` as a logit, ``scale_0..2`` as natural logs of the
standard deviations, ``rot_0..3`` the quaternion (w, x, y, z).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..gaussians import Gaussians
from ._common import StrandFileError
from ._ply import read_ply, write_ply

OPACITY_EPS = 1e-6  # opacities are clipped to [eps, 1 - eps] so their logit is finite
MIN_SCALE = 1e-12  # zero scales (zero-length segments) are written as log(MIN_SCALE)
REST_COUNTS = {0: 0, 9: 1, 24: 2, 45: 3}


def write_3dgs_ply(gaussians: Gaussians, path: str | Path, pad_to_degree: int = 3) -> None:
    """Write ``gaussians``; SH bands missing up to ``pad_to_degree`` are written as zeros
    (viewers commonly expect the 45 ``f_rest`` of degree 3)."""
    g = gaussians
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
    write_ply(path, [("vertex", cols)], comments=["3D Gaussian splats written by cghair"])


def read_3dgs_ply(path: str | Path) -> Gaussians:
    """Read a 3DGS PLY back: sigmoid opacities, exp scales, normalized (w, x, y, z) rotations."""
    ply = read_ply(path)
    v = ply.elements.get("vertex")
    need = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", *(f"scale_{i}" for i in range(3)),
            *(f"rot_{i}" for i in range(4))]
    if v is None or any(n not in v.data for n in need):
        missing = need if v is None else [n for n in need if n not in v.data]
        raise StrandFileError(path, f"not a 3DGS PLY: missing vertex properties {missing}")
    d = {k: np.asarray(a, np.float64) for k, a in v.data.items()}
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
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(norm > 0, q / np.maximum(norm, 1e-30), np.array([1.0, 0, 0, 0]))
    means = np.stack([d["x"], d["y"], d["z"]], 1)
    if not (np.isfinite(means).all() and np.isfinite(sh).all()):
        raise StrandFileError(path, "3DGS PLY has NaN or infinite positions or colours")
    return Gaussians(means=means.astype(np.float32), rotations=q.astype(np.float32),
                     scales=np.exp(np.stack([d[f"scale_{i}"] for i in range(3)], 1)).astype(np.float32),
                     opacities=(1 / (1 + np.exp(-d["opacity"]))).astype(np.float32), sh=sh.astype(np.float32))
