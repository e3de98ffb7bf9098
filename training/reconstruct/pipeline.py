"""``reconstruct``: a multi-view dataset -> strands, stage by stage, each stage checkpointed.

Stages: ``orientation`` (2D Gabor maps of the training views), ``hull`` (visual hull and 3D
orientation field), ``scalp`` (roots on the given mesh or the estimated cap), ``growth`` (strands
along the field), ``refine`` (joint refinement through the differentiable splatter, see
:mod:`.refine`). The checkpoint (``<out>.recon.npz``) holds every finished stage's result; a run
with ``resume`` skips them. Last, the strands are low-passed along their arc length
(:func:`cghair_format.smooth.smooth_strands`, ``smooth_mm``): cheap, so never checkpointed, and a
``resume`` with another width re-smooths the checkpointed strands.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from cghair_format.errors import AssetError
from cghair_format.smooth import RECONSTRUCT_SMOOTH_MM, check_sigma, smooth_strands
from cghair_format.strands import Strands

from .hull import Grid, Hull, ReconstructError, check_masks, orientation_field, pixel_footprint, visual_hull
from .orientation import orientation_map, save_debug
from .prior import BUILTIN as BUILTIN_PRIOR
from .scalp import Roots, check_roots_in_hull, estimate_scalp, load_scalp_mesh, sample_mesh_roots

STAGES = ("orientation", "hull", "scalp", "growth", "refine")
CHECKPOINT_VERSION = 1
# growth keeps this many pixel footprints inside the hull: the closed, dilated masks of strands a
# pixel or more wide make the hull about that much larger than the hair. 4 px: the best of 1 ... 6 by
# grown-strand F1 (3 mm / 30 deg) on harolongo (2000 strands, 128 px splat renders); reported on ruby,
# where it gives 0.606 against 3 px's 0.650: the best inset depends on the model (docs/reconstruct.md,
# "Re-checked on another model")
INSET_PIXELS = 4.0


@dataclass
class ReconstructConfig:
    strands: int = 500
    points_per_strand: int = 32
    hull_resolution: int = 96
    orientations: int = 32
    refine_iters: int = 100
    meters_per_unit: float = 1.0
    seed: int = 0
    backend: str | None = None
    prior: str | None = None  # a strand prior file; None: the built-in basis, "none": no prior
    smooth_mm: float = RECONSTRUCT_SMOOTH_MM  # low-pass width along the strands (mm of arc length); 0: none

    def validate(self) -> ReconstructConfig:
        if self.strands < 1 or self.points_per_strand < 4 or self.hull_resolution < 8 or self.orientations < 4:
            raise ReconstructError("need strands >= 1, points >= 4, hull resolution >= 8, orientations >= 4")
        if self.refine_iters < 0 or not self.meters_per_unit > 0:
            raise ReconstructError("refine iterations must be >= 0 and meters per unit > 0")
        try:
            check_sigma(self.smooth_mm)
        except AssetError as exc:
            raise ReconstructError(str(exc)) from None
        return self


@dataclass
class Result:
    strands: Strands
    grown: Strands
    timings: dict = field(default_factory=dict)
    losses: dict = field(default_factory=dict)


def _up_vector(dataset) -> np.ndarray:
    """The dataset's up axis, else the mean of the cameras' image-up directions."""
    axis = dataset.meta.get("up_axis")
    if axis in ("Y", "Z"):
        return np.array([0.0, 1.0, 0.0]) if axis == "Y" else np.array([0.0, 0.0, 1.0])
    ups = np.stack([-v.camera.camera_to_world[:3, 1] for v in dataset.train])
    u = ups.mean(0)
    return u / np.linalg.norm(u)


def _save_ckpt(path: Path, state: dict) -> None:
    arrays = {k: v for k, v in state.items() if isinstance(v, np.ndarray)}
    meta = {k: v for k, v in state.items() if not isinstance(v, np.ndarray)}
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, _meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
    tmp.replace(path)


def _load_ckpt(path: Path) -> dict:
    try:
        with np.load(path) as z:
            state = {k: z[k] for k in z.files if k != "_meta"}
            state.update(json.loads(bytes(z["_meta"]).decode()))
    except (OSError, ValueError, KeyError) as exc:
        raise ReconstructError(f"{path}: not a reconstruction checkpoint ({exc})") from None
    if state.get("version") != CHECKPOINT_VERSION:
        raise ReconstructError(f"{path}: checkpoint version {state.get('version')}, expected {CHECKPOINT_VERSION}")
    return state


def _strands_state(prefix: str, s: Strands) -> dict:
    return {f"{prefix}_points": s.points, f"{prefix}_offsets": s.offsets}


def _strands_from(state: dict, prefix: str, cfg: ReconstructConfig, up_axis: str) -> Strands:
    return Strands(state[f"{prefix}_points"], state[f"{prefix}_offsets"], meters_per_unit=cfg.meters_per_unit,
                   up_axis=up_axis)


class _Progress:
    """The checkpointed state of a run: which stages are done, their results, timings and losses."""

    def __init__(self, path: Path, state: dict, log):
        self.path, self.state, self.log = path, state, log
        self.timings: dict = state.get("timings", {})
        self.losses: dict = state.get("losses", {})

    def done(self, stage: str) -> bool:
        return stage in self.state["done"]

    def finish(self, stage: str, t0: float, note: str) -> None:
        """Record ``stage`` (begun at ``t0``) as done, save the checkpoint and log ``note``."""
        self.timings[stage] = round(time.perf_counter() - t0, 2)
        self.state["done"].append(stage)
        self.state["timings"], self.state["losses"] = self.timings, self.losses
        _save_ckpt(self.path, self.state)
        self.log(f"[{stage}] {note} ({self.timings[stage]:.1f} s)")


def reconstruct(dataset, config: ReconstructConfig, checkpoint: str | Path, scalp: str | Path | None = None,
                debug_dir: str | Path | None = None, resume: bool = False, log=print) -> Result:
    """Run the stages on ``dataset``'s training views (see the module docstring)."""
    cfg = config.validate()
    views = dataset.train
    check_masks(views)  # before anything long
    mesh = load_scalp_mesh(scalp) if scalp else None
    ckpt = Path(checkpoint)
    state = _load_ckpt(ckpt) if resume else {"version": CHECKPOINT_VERSION, "done": [], "config": asdict(cfg)}
    run = _Progress(ckpt, state, log)
    debug = Path(debug_dir) if debug_dir else None
    if debug:
        debug.mkdir(parents=True, exist_ok=True)
    up = _up_vector(dataset)
    up_axis = "Z" if abs(up[2]) > abs(up[1]) else "Y"
    maps = _orientation_stage(run, views, cfg, debug)
    hull = _hull_stage(run, views, maps, cfg, debug)
    roots = _scalp_stage(run, hull, mesh, scalp, up, cfg)
    grown = _growth_stage(run, hull, roots, views, up, up_axis, cfg)
    result = _refine_stage(run, grown, views, maps, up, up_axis, cfg) if cfg.refine_iters > 0 else grown
    return Result(_smooth_stage(run, result, cfg), grown, run.timings, run.losses)


def _orientation_stage(run: _Progress, views, cfg: ReconstructConfig, debug: Path | None) -> list:
    """The views' orientation maps: cheap to recompute and large to store, so computed on every run."""
    t0 = time.perf_counter()
    maps = [orientation_map(v.image, cfg.orientations) for v in views]
    if debug:
        for v, m in zip(views, maps, strict=True):
            save_debug(m, debug / f"orientation_{v.name}.png")
    conf = float(np.mean([m.confidence[m.mask].mean() for m in maps]))
    if not run.done("orientation"):
        run.finish("orientation", t0, f"{len(maps)} views, mean confidence in the masks {conf:.3f}")
    return maps


def _hull_stage(run: _Progress, views, maps, cfg: ReconstructConfig, debug: Path | None) -> Hull:
    state = run.state
    if run.done("hull"):
        return Hull(Grid(state["grid_origin"], float(state["grid_voxel"]), tuple(state["grid_shape"])),
                    state["occupancy"], state["field"])
    t0 = time.perf_counter()
    hull = orientation_field(visual_hull(views, cfg.hull_resolution), views, maps)
    state.update(grid_origin=hull.grid.origin, grid_voxel=hull.grid.voxel, grid_shape=list(hull.grid.shape),
                 occupancy=hull.occupancy, field=hull.field)
    if debug:
        _save_hull_debug(hull, debug / "hull.png")
    run.finish("hull", t0, f"{int(hull.occupancy.sum())} hair voxels of {hull.grid.voxel:.4g} units")
    return hull


def _scalp_stage(run: _Progress, hull: Hull, mesh, scalp, up: np.ndarray, cfg: ReconstructConfig) -> Roots:
    if run.done("scalp"):
        return Roots(run.state["roots"], run.state["root_normals"])
    t0 = time.perf_counter()
    if mesh is not None:
        roots = sample_mesh_roots(mesh, cfg.strands, cfg.seed)
        check_roots_in_hull(roots, hull, f"scalp mesh {scalp}")
        how = f"sampled on {scalp}"
    else:
        roots = estimate_scalp(hull, up, cfg.strands, cfg.seed)
        how = "on the scalp estimated from the hull"
    run.state.update(roots=roots.points, root_normals=roots.normals)
    run.finish("scalp", t0, f"{len(roots.points)} roots {how}")
    return roots


def _growth_stage(run: _Progress, hull: Hull, roots: Roots, views, up: np.ndarray, up_axis: str,
                  cfg: ReconstructConfig) -> Strands:
    from .grow import grow_strands

    if run.done("growth"):
        return _strands_from(run.state, "grown", cfg, up_axis)
    t0 = time.perf_counter()
    grown = grow_strands(hull, roots, up, cfg.points_per_strand, meters_per_unit=cfg.meters_per_unit,
                         up_axis=up_axis, inset=INSET_PIXELS * pixel_footprint(hull, views))
    if grown.count == 0:
        raise ReconstructError("no strand grew from the roots: the scalp lies outside the hair volume")
    run.state.update(_strands_state("grown", grown))
    lengths = np.linalg.norm(np.diff(grown.to_array(), axis=1), axis=2).sum(1)
    run.finish("growth", t0, f"{grown.count} strands, median length {np.median(lengths):.4g} units")
    return grown


def _refine_stage(run: _Progress, grown: Strands, views, maps, up: np.ndarray, up_axis: str,
                  cfg: ReconstructConfig) -> Strands:
    if run.done("refine"):
        return _strands_from(run.state, "refined", cfg, up_axis)
    from .prior import StrandPrior
    from .refine import refine_strands

    t0 = time.perf_counter()
    strand_prior = None if cfg.prior == "none" else StrandPrior.load(cfg.prior or BUILTIN_PRIOR)
    result, hist = refine_strands(grown, views, maps, cfg, up, strand_prior, log=run.log)
    run.losses["refine"] = hist
    run.state.update(_strands_state("refined", result))
    run.finish("refine", t0, f"loss {hist[0]:.4f} -> {hist[-1]:.4f} over {cfg.refine_iters} iterations")
    return result


def _smooth_stage(run: _Progress, strands: Strands, cfg: ReconstructConfig) -> Strands:
    """The strands low-passed with ``cfg.smooth_mm``; timed, not checkpointed (it takes a second)."""
    if cfg.smooth_mm == 0:
        return strands
    t0 = time.perf_counter()
    smoothed = smooth_strands(strands, cfg.smooth_mm)
    moved = np.linalg.norm(smoothed.points - strands.points, axis=1)
    run.timings["smooth"] = round(time.perf_counter() - t0, 2)
    run.log(f"[smooth] {cfg.smooth_mm:g} mm along the strands: points moved by {np.median(moved):.4g} units "
            f"(median), {moved.max():.4g} at most ({run.timings['smooth']:.1f} s)")
    return smoothed


def _save_hull_debug(hull: Hull, path: Path) -> None:
    """Three max projections of the hull, tinted by the field's confidence."""
    from PIL import Image

    conf = np.trace(hull.field, axis1=3, axis2=4)
    tiles = []
    for axis in range(3):
        occ = hull.occupancy.any(axis)
        c = conf.max(axis)
        img = np.stack([occ * 0.3 + c * 0.7, occ * 0.3, occ * 0.3], -1)
        tiles.append((np.clip(img, 0, 1) * 255).astype(np.uint8))
    h = max(t.shape[0] for t in tiles)
    tiles = [np.pad(t, ((0, h - t.shape[0]), (0, 2), (0, 0))) for t in tiles]
    Image.fromarray(np.concatenate(tiles, 1)).save(path)


__all__ = ["STAGES", "ReconstructConfig", "Result", "reconstruct"]
