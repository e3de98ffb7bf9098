"""Strand reconstruction metrics: the paper's position and curvature errors and HairGS's
precision / recall / F1 at distance and angle thresholds.

Both strand sets are first resampled to points ``step`` apart along each strand (1 mm by default,
so the nearest-point distance overstates the distance to the polyline by at most half a step);
every point carries its undirected segment direction and its discrete curvature. Distances are in
millimetres, converted from each file's ``meters_per_unit``.

- position error, recon -> GT: mean distance from each reconstructed point to the nearest
  ground-truth point (the paper's direction); GT -> recon is reported too (a reconstruction that
  covers only half of the hair has a small recon -> GT error and a large GT -> recon one).
- curvature error: mean ``|k_recon - k_gt|`` (1/m) between each reconstructed point and its
  nearest ground-truth point.
- precision at (d, a): fraction of reconstructed points with a ground-truth point closer than
  ``d`` whose direction differs by less than ``a``; recall: the same over ground-truth points;
  F1 their harmonic mean.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cghair_format.errors import CghError
from cghair_format.strands import Strands

THRESHOLDS = ((2.0, 20.0), (3.0, 30.0), (4.0, 40.0))  # (mm, degrees), HairGS's
DEFAULT_STEP_MM = 1.0
FIRST_NEIGHBOURS = 16  # k-nearest tried first; points whose k all lie within d are re-queried by ball
MAX_POINTS = 20_000_000  # after resampling; beyond this the KD-trees need several GiB


class StrandMetricsError(CghError, ValueError):
    """Strands that cannot be compared (empty, or far too many points at this step)."""


@dataclass
class SampledStrands:
    points: np.ndarray  # [N, 3] float64, millimetres
    directions: np.ndarray  # [N, 3] unit tangents
    curvature: np.ndarray  # [N] 1/m


@dataclass
class StrandMetrics:
    position_error_mm: float  # recon -> GT
    position_error_gt_mm: float  # GT -> recon
    curvature_error: float  # 1/m, recon -> nearest GT
    scores: list[dict] = field(default_factory=list)  # {distance_mm, angle_deg, precision, recall, f1}
    recon_points: int = 0
    gt_points: int = 0
    step_mm: float = DEFAULT_STEP_MM

    def f1(self, distance_mm: float) -> float:
        return next(s["f1"] for s in self.scores if s["distance_mm"] == distance_mm)

    def to_dict(self) -> dict:
        return {"position_error_mm": self.position_error_mm, "position_error_gt_mm": self.position_error_gt_mm,
                "curvature_error_per_m": self.curvature_error, "scores": self.scores,
                "recon_points": self.recon_points, "gt_points": self.gt_points, "step_mm": self.step_mm}

    def summary(self) -> str:
        lines = [f"position error {self.position_error_mm:.3f} mm (recon -> GT), "
                 f"{self.position_error_gt_mm:.3f} mm (GT -> recon); "
                 f"curvature error {self.curvature_error:.2f} 1/m"]
        for s in self.scores:
            lines.append(f"  {s['distance_mm']:g} mm / {s['angle_deg']:g} deg: precision {s['precision']:.3f}, "
                         f"recall {s['recall']:.3f}, F1 {s['f1']:.3f}")
        return "\n".join(lines)


def sample_strands(strands: Strands, step_mm: float = DEFAULT_STEP_MM,
                   meters_per_unit: float | None = None) -> SampledStrands:
    """Points every ``step_mm`` along each strand (and its last point), in millimetres."""
    scale = 1000.0 * (meters_per_unit if meters_per_unit is not None else strands.meters_per_unit)
    pts = strands.points.astype(np.float64) * scale
    off = strands.offsets
    counts = np.diff(off)
    keep = counts >= 2
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    seg[off[1:-1] - 1] = 0.0  # no segment across strand boundaries
    cum = np.concatenate([[0.0], np.cumsum(seg)])  # global arc length at each point
    start, end = cum[off[:-1]], cum[np.maximum(off[1:] - 1, off[:-1])]
    lengths = np.where(keep, end - start, 0.0)
    # a last piece shorter than 1e-4 step (float32 round-off) is dropped
    n_new = np.where(keep & (lengths > 0), np.ceil(lengths / step_mm - 1e-4).astype(np.int64) + 1, 0)
    if n_new.sum() > MAX_POINTS:
        raise StrandMetricsError(f"{int(n_new.sum())} points at a {step_mm} mm step: check the scale "
                                 "(--meters-per-unit) or use a larger --step-mm")
    if n_new.sum() == 0:
        raise StrandMetricsError("no strand with two or more distinct points to compare")
    new_sid = np.repeat(np.arange(len(counts)), n_new)
    new_off = np.concatenate([[0], np.cumsum(n_new)])
    k = np.arange(int(n_new.sum())) - new_off[new_sid]
    t = start[new_sid] + np.minimum(k * step_mm, lengths[new_sid])
    # interpolate on the global arc length; strand boundaries have zero-length gaps, and ties
    # resolve within the strand because t lies inside [start, end] of its own strand
    idx = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, len(pts) - 2)
    idx = np.clip(idx, off[new_sid], np.maximum(off[new_sid + 1] - 2, off[new_sid]))
    denom = np.where(seg[idx] > 0, seg[idx], 1.0)
    w = np.clip((t - cum[idx]) / denom, 0.0, 1.0)[:, None]
    p = pts[idx] * (1 - w) + pts[idx + 1] * w
    return _with_frames(p, new_off)


def _with_frames(p: np.ndarray, off: np.ndarray) -> SampledStrands:
    """Unit tangents (central differences, one-sided at the ends) and discrete curvature."""
    n = len(p)
    first, last = off[:-1][np.diff(off) > 0], off[1:][np.diff(off) > 0] - 1
    prev_i = np.arange(n) - 1
    next_i = np.arange(n) + 1
    prev_i[first] = first
    next_i[last] = last
    tan = p[next_i] - p[prev_i]
    tan /= np.maximum(np.linalg.norm(tan, axis=1, keepdims=True), 1e-12)
    a = p - p[prev_i]
    b = p[next_i] - p
    la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    cosang = np.einsum("ij,ij->i", a, b) / np.maximum(la * lb, 1e-12)
    ang = np.arccos(np.clip(cosang, -1.0, 1.0))
    curv = np.where((la > 0) & (lb > 0), ang / np.maximum(0.5 * (la + lb), 1e-12), 0.0) * 1000.0  # 1/mm -> 1/m
    long = last > first  # ends take their neighbour's curvature
    curv[first[long]] = curv[first[long] + 1]
    curv[last[long]] = curv[last[long] - 1]
    return SampledStrands(p, tan, curv)


def _matched(query: SampledStrands, tree, ref: SampledStrands, distance: float, cos_limit: float) -> np.ndarray:
    """For each query point: is there a reference point within ``distance`` at an angle < the limit?"""
    k = min(FIRST_NEIGHBOURS, len(ref.points))
    dist, idx = tree.query(query.points, k=k, distance_upper_bound=distance)
    dist, idx = dist.reshape(len(query.points), k), idx.reshape(len(query.points), k)
    found = np.isfinite(dist)
    safe = np.where(found, idx, 0)
    cos = np.abs(np.einsum("nkj,nj->nk", ref.directions[safe], query.directions))
    ok = (found & (cos > cos_limit)).any(axis=1)
    # points with all k neighbours inside the radius and none aligned may have an aligned one further out
    todo = np.flatnonzero(~ok & found.all(axis=1))
    for i in todo:
        near = tree.query_ball_point(query.points[i], distance)
        ok[i] = bool((np.abs(ref.directions[near] @ query.directions[i]) > cos_limit).any())
    return ok


def compare(recon: SampledStrands, gt: SampledStrands, thresholds=THRESHOLDS,
            step_mm: float = DEFAULT_STEP_MM) -> StrandMetrics:
    from scipy.spatial import cKDTree

    gt_tree, recon_tree = cKDTree(gt.points), cKDTree(recon.points)
    d_rg, i_rg = gt_tree.query(recon.points)
    d_gr, _ = recon_tree.query(gt.points)
    curv = float(np.abs(recon.curvature - gt.curvature[i_rg]).mean())
    scores = []
    for dist, ang in thresholds:
        c = float(np.cos(np.radians(ang)))
        p = float(_matched(recon, gt_tree, gt, dist, c).mean())
        r = float(_matched(gt, recon_tree, recon, dist, c).mean())
        f1 = 2 * p * r / (p + r) if p + r > 0 else 0.0
        scores.append({"distance_mm": dist, "angle_deg": ang, "precision": p, "recall": r, "f1": f1})
    return StrandMetrics(float(d_rg.mean()), float(d_gr.mean()), curv, scores,
                         len(recon.points), len(gt.points), step_mm)


def evaluate_strands(recon: Strands, gt: Strands, *, step_mm: float = DEFAULT_STEP_MM,
                     meters_per_unit: float | None = None, thresholds=THRESHOLDS) -> StrandMetrics:
    """Metrics of ``recon`` against ``gt``; ``meters_per_unit`` overrides both files' scale."""
    for name, s in (("reconstruction", recon), ("ground truth", gt)):
        if s.count == 0:
            raise StrandMetricsError(f"the {name} has no strands")
    return compare(sample_strands(recon, step_mm, meters_per_unit), sample_strands(gt, step_mm, meters_per_unit),
                   thresholds, step_mm)
