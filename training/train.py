"""The training loop: dataset + cards -> trained model -> .cgh, with checkpoints and resume.

A run is set up (:func:`start_run`: the dataset, the model from cards or from a checkpoint, the
optimiser and its :class:`~training.schedule.Schedule`), stepped (:func:`train_step`: render one view,
the loss, backward, the optimiser step) from its first to its last iteration (:func:`run_iterations`:
the history, the progress bar, the checkpoints) and finished (:func:`finish`: the last checkpoint, the
export, the summary and the files).
"""

from __future__ import annotations

import ctypes
import json
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from cghair_format.asset import HairAsset
from cghair_format.atomic import atomic_path, write_text
from cghair_format.codec import EncodeReport
from cghair_format.errors import CghError
from cghair_format.profiles import Profile, get_profile
from cghair_format.strands import Strands

from . import losses
from .backends import renderer, resolve_backend
from .children import PROJECT_EVERY, FollowingChildren, following_children
from .config import RunOptions, TrainConfig
from .datasets.read import read_dataset
from .datasets.types import Dataset, View
from .model import HairModel, tau_at
from .schedule import Schedule
from .smooth_moves import SmoothMoves
from .splatter import torch_device
from .visibility import negligible_segments

CHECKPOINT_VERSION = 1
# glibc mallopt parameters and their defaults (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
DEFAULT_TRIM_THRESHOLD, DEFAULT_MMAP_MAX = 128 * 1024, 65536
EXPORT_PROBE_VIEWS = 4  # training views used to choose hard or soft weights at export
STAGES = ("model", "render", "loss", "backward", "step")


class TrainError(CghError, ValueError):
    """Training cannot start or resume with these inputs."""


@dataclass
class TrainResult:
    model: HairModel
    base: HairAsset  # the card-built asset the model started from
    config: TrainConfig
    asset: HairAsset | None = None  # the exported asset (None for variants without a .cgh encoding)
    weight_mode: str | None = None  # "soft" or "hard", chosen by measurement
    export_psnr: dict = field(default_factory=dict)  # weight mode -> PSNR of its file as written, on the probe views
    history: list[dict] = field(default_factory=list)  # iteration, loss, psnr
    seconds: float = 0.0
    stage_seconds: dict = field(default_factory=dict)
    iterations_run: int = 0
    out_path: Path | None = None
    backend: str = "reference"  # the rasterizer that trained it (training.backends)


def base_asset(config: TrainConfig, strands: Strands | str | Path | None = None,
               cards: HairAsset | str | Path | None = None, progress: bool = True) -> HairAsset:
    """The untrained asset: ``cards`` as given (a .cgh path or HairAsset), else cards built from
    ``strands`` (a Strands or any file :func:`cghair_format.exchange.load_strands` reads)."""
    if cards is not None:
        if isinstance(cards, HairAsset):
            return cards.validate()
        from cghair_format import read

        return read(cards)
    if strands is None:
        raise TrainError("training needs strands (to build cards from) or a .cgh with cards")
    if not isinstance(strands, Strands):
        path = Path(strands)
        if path.suffix.lower() == ".cgh":
            return base_asset(config, cards=path, progress=progress)
        from cghair_format.exchange import load_strands

        strands = load_strands(path)
    from cghair_format.cards import build_cards

    build = build_cards(strands, n_cards=config.n_cards, n_groups=config.n_groups,
                        segments=config.card_segments, points=config.points_per_strand, seed=config.seed,
                        progress=progress, sh_degree=config.sh_degree, log=None)
    return build.asset


def _targets(views: list[View], background) -> tuple[torch.Tensor, torch.Tensor]:
    rgb = np.stack([v.premultiplied(background) for v in views]).astype(np.float32)
    mask = np.stack([v.image[..., 3] for v in views]).astype(np.float32)
    return torch.as_tensor(rgb), torch.as_tensor(mask)


def mean_hair_colour(views: list[View]) -> tuple[float, float, float]:
    img = np.stack([v.image for v in views])
    a = img[..., 3:4]
    total = float(a.sum())
    if total <= 0:
        return (0.3, 0.2, 0.12)
    return tuple(float(x) for x in (img[..., :3] * a).sum((0, 1, 2)) / total)


def _scene_scale(asset: HairAsset) -> float:
    spine = asset.cards.spine.reshape(-1, 3)
    return float(np.linalg.norm(spine.max(0) - spine.min(0))) or 1.0


def save_checkpoint(path: Path, *, model: HairModel, optimizer: torch.optim.Optimizer, config: TrainConfig,
                    base: HairAsset, iteration: int, history: list[dict], dataset: str, seconds: float) -> None:
    """``seconds``: training time of every run up to ``iteration``, so that a resumed run reports the total."""
    from cghair_format import encode

    state = {
        "version": CHECKPOINT_VERSION, "iteration": iteration, "config": config.to_dict(),
        "model": model.state_dict(), "optimizer": optimizer.state_dict(),
        "base_cgh": encode(base, "lossless")[0], "history": history, "dataset": dataset,
        "rng": torch.get_rng_state(), "seconds": seconds,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        torch.save(state, tmp)


def load_checkpoint(path: str | Path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise TrainError(f"checkpoint {path} does not exist")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several unrelated types for a bad file
        raise TrainError(f"{path} is not a readable training checkpoint ({type(exc).__name__}: {exc})") from exc
    if not isinstance(state, dict) or state.get("version") != CHECKPOINT_VERSION:
        got = state.get("version") if isinstance(state, dict) else "?"
        raise TrainError(f"{path}: unsupported checkpoint version {got}"
                         f" (this trainer reads version {CHECKPOINT_VERSION})")
    return state


def choose_export(model: HairModel, base: HairAsset, views: list[View], config: TrainConfig,
                  profile: str | Profile, device: str | torch.device = "cpu", backend: str = "reference",
                  negligible: np.ndarray | None = None, opacity_budget: float | None = None
                  ) -> tuple[HairAsset | None, str | None, dict, EncodeReport | None]:
    """Export with hard and with soft weights, encode each with ``profile`` and the ``negligible`` marks
    as the file will be written (:func:`cghair_format.encode`; its metadata, which codes apart, aside),
    decode it, and keep the one with the higher PSNR on a few training views (rendered on the torch
    ``device`` with ``backend``): the asset, its mode, each mode's PSNR and the kept one's EncodeReport."""
    from cghair_format import decode, decode_gaussians, encode

    from .backends import render_gaussians

    if model.export_refusal() is not None:
        return None, None, {}, None
    tau = tau_at(config, config.iterations)
    probe = views[:: max(1, len(views) // EXPORT_PROBE_VIEWS)][:EXPORT_PROBE_VIEWS]
    target, _ = _targets(probe, config.background)
    scores, assets, reports = {}, {}, {}
    for mode in ("hard", "soft"):
        asset = model.to_asset(base, mode, tau)
        data, reports[mode] = encode(asset, profile, negligible=negligible, opacity_budget=opacity_budget)
        g = decode_gaussians(decode(data))
        rgbs = [render_gaussians(g, v.camera, tuple(config.background), device, backend)["rgb"] for v in probe]
        scores[mode] = losses.psnr(torch.as_tensor(np.stack(rgbs)), target)
        assets[mode] = asset
    best = max(scores, key=scores.get)
    return assets[best], best, scores, reports[best]


@contextmanager
def heap_kept() -> Iterator[None]:
    """Freed memory stays in the process heap, for the next iteration's tensors of the same sizes.

    glibc serves each large tensor (a large asset's iteration makes several of hundreds of MB) with a fresh
    mmap and unmaps it on free, so every iteration page-faults and zeroes them anew. Here large
    blocks come from the heap and the heap is not trimmed while training; afterwards glibc's
    defaults come back and the heap is trimmed. A no-op where the C library is not glibc.
    """
    try:
        libc = ctypes.CDLL(None)
        mallopt, trim = libc.mallopt, libc.malloc_trim
    except (OSError, AttributeError):
        yield
        return
    mallopt(M_MMAP_MAX, 0)
    mallopt(M_TRIM_THRESHOLD, 2**31 - 1)
    try:
        yield
    finally:
        mallopt(M_MMAP_MAX, DEFAULT_MMAP_MAX)
        mallopt(M_TRIM_THRESHOLD, DEFAULT_TRIM_THRESHOLD)
        trim(0)


@dataclass
class Run:
    """What one run works with, from :func:`start_run` to :func:`finish`."""

    config: TrainConfig
    options: RunOptions
    views: list[View]  # the training views
    dataset_name: str
    base: HairAsset
    model: HairModel
    optimizer: torch.optim.Optimizer
    schedule: Schedule
    render: Callable  # training.backends.renderer of ``backend``
    backend: str
    device: torch.device
    targets: torch.Tensor  # [V, H, W, 3] the views composited over the background
    masks: torch.Tensor  # [V, H, W] their alpha
    start: int  # the first iteration of this run (after a resumed checkpoint's)
    end: int  # one past its last
    history: list[dict]
    seconds_before: float  # training time of the runs before a resumed checkpoint
    stage: dict = field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))  # seconds per stage
    predictor: losses.CoderPredictor | None = None  # the strand coder's, for the rate term (None: no rate term)
    children: FollowingChildren | None = None  # the interpolated strands that follow their guides (None: none)
    smooth: SmoothMoves | None = None  # keeps the other strands' moves smooth (None: every point moves on its own)

    def clock(self) -> float:
        """Now; on a GPU after waiting for the kernels (they run asynchronously), so that each stage is timed."""
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        return time.perf_counter()

    def save(self, iteration: int, seconds: float) -> None:
        """Write the checkpoint (if the run has a path for one) after ``iteration`` and ``seconds`` of this run."""
        path = self.options.checkpoint_path()
        if path is not None:
            save_checkpoint(path, model=self.model, optimizer=self.optimizer, config=self.config, base=self.base,
                            iteration=iteration, history=self.history, dataset=self.dataset_name,
                            seconds=self.seconds_before + seconds)


def _starting_point(config: TrainConfig | None, options: RunOptions, strands, cards
                    ) -> tuple[TrainConfig, HairAsset, dict | None]:
    """The config, the card-built asset and the checkpoint (None: a fresh run) a run starts from. A
    resumed run keeps its checkpoint's config, except how it ends (``iterations``, ``opacity_budget``)
    when ``config`` is given."""
    if options.resume is None:
        config = (config or TrainConfig()).validate()
        return config, base_asset(config, strands, cards, options.progress), None
    from cghair_format import decode

    state = load_checkpoint(options.resume)
    saved = TrainConfig.from_dict(state["config"])
    if config is not None:  # how the run ends is the caller's
        saved.iterations, saved.opacity_budget = config.iterations, config.opacity_budget
    return saved, decode(state["base_cgh"]), state


def start_run(dataset: Dataset | str | Path, config: TrainConfig | None, options: RunOptions,
              strands=None, cards=None) -> Run:
    """Read the dataset, build (or resume) the model and its optimiser, and check that the strands
    sit where the views see hair before any iteration runs."""
    from cghair_format.gaussians import decode_strands

    from .datasets.alignment import check_strands_in_views

    device = torch_device(options.device)
    backend = resolve_backend(options.backend, device)
    if options.threads:
        torch.set_num_threads(options.threads)
    ds = dataset if isinstance(dataset, Dataset) else read_dataset(dataset)
    config, base, state = _starting_point(config, options, strands, cards)
    check_strands_in_views(decode_strands(base).points, ds.train)  # another frame: refuse now, not after hours
    torch.manual_seed(config.seed)
    model = HairModel(base, config, mean_hair_colour(ds.train)).to(options.device)
    # fused: one kernel per parameter for the whole update, several times faster than the loop on the
    # CPU (training/ABLATION.md, "Around the rasterizer")
    optimizer = torch.optim.Adam(model.param_groups(config, _scene_scale(base)), eps=1e-15, fused=True)
    schedule = Schedule(config, model, optimizer, len(ds.train))
    start, history, seconds_before = 0, [], 0.0
    if state is not None:
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])  # moves the moments to the parameters' device
        history, start = list(state["history"]), int(state["iteration"])
        seconds_before = float(state.get("seconds", 0.0))  # (checkpoints before it was kept: unknown, 0)
        torch.set_rng_state(state["rng"])
    targets, masks = (t.to(options.device) for t in _targets(ds.train, config.background))
    end = config.iterations if options.stop_at is None else max(start, min(options.stop_at, config.iterations))
    moves = end > config.geometry_frozen_iters
    # (finding the children takes 5 s at the paper's scale: only for a run whose geometry moves)
    children = following_children(base, options.profile) if moves and config.children_follow else None
    smooth = None
    if moves and config.geometry_controls:
        smooth = SmoothMoves(base, config.geometry_controls, None if children is None else children.child, device)
    return Run(config, options, ds.train, str(dataset) if not isinstance(dataset, Dataset) else "<in memory>",
               base, model, optimizer, schedule, renderer(backend), backend, device, targets, masks, start, end,
               history, seconds_before, predictor=coder_predictor(base, config, options.profile, device),
               children=children, smooth=smooth)


def coder_predictor(base: HairAsset, config: TrainConfig, profile: str | Profile,
                    device: torch.device | str = "cpu") -> losses.CoderPredictor | None:
    """The strand coder's predictor for the rate term (:func:`training.losses.geometry_rate`), on the
    profile's first base stride, with residuals counted in steps of twice the profile's position tolerance
    (the width of the writer's dead zone, inside which a refinement residual codes as zero); None when
    ``config.geometry_rate`` is 0."""
    if config.geometry_rate <= 0:
        return None
    from cghair_format.gaussians import decode_strands

    prof = get_profile(profile)
    step = 2 * prof.position_tolerance * decode_strands(base).bbox_diagonal()
    return losses.CoderPredictor(base.points_per_strand, prof.base_strides[0], base.counts, step, device)


def train_step(run: Run, iteration: int) -> tuple[float, float, float]:
    """One iteration: render its view, the loss, backward, the optimiser step. Returns the loss, the
    PSNR of the rendered view and the Gumbel temperature."""
    it = run.schedule.apply(iteration)
    config = run.config
    t0 = run.clock()
    means, quats, scales, opacities, sh = run.model.training_inputs(it.tau)
    t1 = run.clock()
    out = run.render(means, quats, scales, opacities, sh, run.views[it.view].camera, tuple(config.background))
    t2 = run.clock()
    target = run.targets[it.view]
    loss = (losses.image_loss(out.rgb, target, config.lambda_dssim)
            + config.lambda_alpha * losses.l1(out.alpha, run.masks[it.view])
            + config.lambda_opacity_smooth * run.model.opacity_smoothness())
    if it.geometry_on and run.predictor is not None:
        loss = loss + config.geometry_rate * losses.geometry_rate(run.model.points(), run.predictor)
    t3 = run.clock()
    run.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    follow = it.geometry_on and run.children is not None
    if follow:
        run.children.hold(run.model.uv, run.model.delta)
    t4 = run.clock()
    run.optimizer.step()
    if it.geometry_on and run.smooth is not None:
        run.smooth.project(run.model.uv, run.model.delta)
    if follow and (iteration + 1) % PROJECT_EVERY == 0:
        run.children.project(run.model.uv, run.model.delta)
    t5 = run.clock()
    for name, dt in zip(STAGES, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4), strict=True):
        run.stage[name] += dt
    if not torch.isfinite(loss.detach()):
        raise TrainError(f"the loss became {float(loss.detach())} at iteration {iteration}; lower the learning rates")
    return float(loss.detach()), losses.psnr(out.rgb, target), it.tau


def run_iterations(run: Run) -> float:
    """Step ``run`` from its start to its end, recording the history every ``log_every`` iterations and
    checkpointing every ``checkpoint_every``; returns the seconds it took."""
    config, bar = run.config, None
    t_start = time.perf_counter()
    if run.options.progress:
        from tqdm import tqdm

        bar = tqdm(total=config.iterations, initial=run.start, desc=f"train {config.variant}", unit="it",
                   file=run.options.log)
    running_loss, running_psnr = [], []
    with heap_kept():
        for it in range(run.start, run.end):
            loss, psnr, tau = train_step(run, it)
            running_loss.append(loss)
            running_psnr.append(psnr)
            if (it + 1) % config.log_every == 0 or it + 1 == config.iterations:
                rec = {"iteration": it + 1, "loss": float(np.mean(running_loss)), "psnr": float(np.mean(running_psnr)),
                       "tau": tau}
                run.history.append(rec)
                running_loss, running_psnr = [], []
                if bar is not None:
                    bar.set_postfix(loss=f"{rec['loss']:.4f}", psnr=f"{rec['psnr']:.2f}")
            if bar is not None:
                bar.update(1)
            if (it + 1) % config.checkpoint_every == 0:
                run.save(it + 1, time.perf_counter() - t_start)
    if bar is not None:
        bar.close()
    if run.children is not None and run.start < run.end and run.end % PROJECT_EVERY:
        run.children.project(run.model.uv, run.model.delta)  # the moves since the last projection too
    return time.perf_counter() - t_start


@dataclass
class Marks:
    """The segments whose opacities the writer may lower (:func:`training.visibility.negligible_segments`;
    None: none), their budget, the seconds marking took, and the kept export's EncodeReport."""

    negligible: np.ndarray | None = None
    budget: float | None = None
    seconds: float = 0.0
    report: EncodeReport | None = None

    @property
    def kept(self) -> int | None:
        """The opacities the writer lowered: 0 where the plain stream coded smaller; None without marks."""
        if self.negligible is None:
            return None
        return self.report.opacity.marked if self.report.opacity.kept else 0


def export(run: Run, result: TrainResult) -> Marks:
    """Fill ``result``'s exported asset, weight mode and the PSNRs of each mode's file as written, marks
    and all (:func:`choose_export`); the marks rest on geometry and opacity, the same in either mode."""
    config, profile, marks = run.config, run.options.profile, Marks()
    t0 = time.perf_counter()  # (an export step, not one of the iterations' stages)
    if (run.model.export_refusal() is None and run.options.out is not None and config.opacity_budget > 0
            and not get_profile(profile).lossless):
        marks.negligible = negligible_segments(run.model.to_asset(run.base), run.views, config.opacity_budget,
                                               run.backend, run.device)
        marks.budget = config.opacity_budget
    marks.seconds = time.perf_counter() - t0
    result.asset, result.weight_mode, result.export_psnr, marks.report = choose_export(
        run.model, run.base, run.views, config, profile, run.device, run.backend, marks.negligible, marks.budget)
    return marks


def summary(run: Run, result: TrainResult, marks: Marks) -> dict:
    """The figures of a finished run, saved in the asset's metadata and as ``<out>.train.json``."""
    return {
        "config": run.config.to_dict(), "dataset": run.dataset_name, "backend": run.backend,
        "iterations_run": result.iterations_run, "seconds": round(result.seconds, 3),
        "seconds_total": round(run.seconds_before + result.seconds, 3),
        "stage_seconds": {k: round(v, 3) for k, v in run.stage.items()},
        "final": run.history[-1] if run.history else None, "weight_mode": result.weight_mode,
        "export_psnr": result.export_psnr, "appearance_parameters": run.model.appearance_parameters(),
        "gaussians": run.model.n_gaussians,
        "negligible_segments": marks.kept,  # the opacities the writer lowered
        "negligible_seconds": round(marks.seconds, 3),
    }


def finish(run: Run, seconds: float) -> TrainResult:
    """Write the last checkpoint; after the last iteration of the config also export the model and
    write the .cgh and ``<out>.train.json`` (a run stopped early exports nothing)."""
    run.save(run.end, seconds)
    out = Path(run.options.out) if run.options.out is not None else None
    result = TrainResult(run.model, run.base, run.config, history=run.history, seconds=seconds,
                         stage_seconds=run.stage, iterations_run=run.end - run.start, out_path=out,
                         backend=run.backend)
    if run.end < run.config.iterations:
        return result
    marks = export(run, result)
    facts = summary(run, result, marks)
    if result.asset is not None:
        result.asset.metadata["training"] = facts
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_text(out.with_suffix(".train.json"), json.dumps(facts, indent=2) + "\n")
        if result.asset is not None:
            from cghair_format import write

            write(result.asset, out, run.options.profile, negligible=marks.negligible, opacity_budget=marks.budget)
    return result


def train(dataset: Dataset | str | Path, *, strands: Strands | str | Path | None = None,
          cards: HairAsset | str | Path | None = None, out: str | Path | None = None,
          config: TrainConfig | None = None, resume: str | Path | None = None,
          checkpoint: str | Path | None = None, profile: str | Profile = "compact", progress: bool = True,
          log=None, threads: int | None = None, stop_at: int | None = None,
          device: str = "cpu", backend: str | None = None) -> TrainResult:
    """Fit the model to the dataset's training views and write ``out`` (.cgh) if given.

    ``checkpoint`` (default ``<out>.ckpt.pt``) is written every ``config.checkpoint_every``
    iterations and at the end; ``resume`` continues from one (its config wins, except
    ``iterations`` and ``opacity_budget`` when ``config`` is given). The config and final figures are saved in
    ``asset.metadata["training"]`` and as ``<out>.train.json``. ``device`` is a torch device
    ("cpu", "cuda"); the splatter follows it. ``backend`` is the rasterizer (:mod:`training.backends`;
    default: the fastest one that runs on ``device``). ``stop_at`` ends the run after
    that iteration as if interrupted (checkpoint written, nothing exported); resume continues it.
    The keyword arguments other than ``strands``, ``cards`` and ``config`` are :class:`RunOptions`.
    """
    options = RunOptions(out=out, checkpoint=checkpoint, resume=resume, profile=profile, progress=progress,
                         log=log if log is not None else sys.stderr, threads=threads, stop_at=stop_at,
                         device=device, backend=backend)
    run = start_run(dataset, config, options, strands, cards)
    return finish(run, run_iterations(run))
