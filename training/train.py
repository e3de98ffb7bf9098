"""The training loop: dataset + cards -> trained model -> .cgh, with checkpoints and resume."""

from __future__ import annotations

import ctypes
import json
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from cghair_format.asset import HairAsset
from cghair_format.atomic import atomic_path, write_text
from cghair_format.codec import EncodeReport
from cghair_format.errors import CghError
from cghair_format.profiles import get_profile
from cghair_format.strands import Strands

from . import losses
from .backends import renderer, resolve_backend
from .config import TrainConfig
from .dataset import Dataset, View, read_dataset
from .model import HairModel, tau_at
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


def view_at(seed: int, iteration: int, n_views: int) -> int:
    """The training view of an iteration: a fresh permutation of the views every epoch, derived
    from the seed and the epoch alone so that a resumed run sees the same views."""
    epoch, index = divmod(iteration, n_views)
    return int(np.random.default_rng([seed, epoch]).permutation(n_views)[index])


def _lr_factor(config: TrainConfig, iteration: int) -> float:
    frac = min(1.0, iteration / max(1, config.iterations))
    return config.lr_final_factor ** frac


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
                  profile: str, device: str | torch.device = "cpu", backend: str = "reference",
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


def train(dataset: Dataset | str | Path, *, strands: Strands | str | Path | None = None,
          cards: HairAsset | str | Path | None = None, out: str | Path | None = None,
          config: TrainConfig | None = None, resume: str | Path | None = None,
          checkpoint: str | Path | None = None, profile: str = "compact", progress: bool = True,
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
    """
    log = log if log is not None else sys.stderr
    dev = torch_device(device)
    backend = resolve_backend(backend, dev)
    render = renderer(backend)
    if threads:
        torch.set_num_threads(threads)
    ds = dataset if isinstance(dataset, Dataset) else read_dataset(dataset)
    dataset_name = str(dataset) if not isinstance(dataset, Dataset) else "<in memory>"
    state = None
    if resume is not None:
        state = load_checkpoint(resume)
        cfg = TrainConfig.from_dict(state["config"])
        if config is not None:  # how the run ends is the caller's
            cfg.iterations, cfg.opacity_budget = config.iterations, config.opacity_budget
        config = cfg
        from cghair_format import decode

        base = decode(state["base_cgh"])
    else:
        config = (config or TrainConfig()).validate()
        base = base_asset(config, strands, cards, progress)
    from cghair_format.gaussians import decode_strands

    from .capture import check_strands_in_views

    # strands in another frame: refuse now, not after hours
    check_strands_in_views(decode_strands(base).points, ds.train)
    torch.manual_seed(config.seed)
    model = HairModel(base, config, mean_hair_colour(ds.train)).to(device)
    # fused: one kernel per parameter for the whole update, several times faster than the loop on the
    # CPU (docs/ablation.md, "Around the rasterizer")
    optimizer = torch.optim.Adam(model.param_groups(config, _scene_scale(base)), eps=1e-15, fused=True)
    base_lr = {g["name"]: g["lr"] for g in optimizer.param_groups}
    history: list[dict] = []
    start, seconds_before = 0, 0.0
    if state is not None:
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])  # moves the moments to the parameters' device
        history = list(state["history"])
        start = int(state["iteration"])
        seconds_before = float(state.get("seconds", 0.0))  # (checkpoints before it was kept: unknown, 0)
        torch.set_rng_state(state["rng"])
    out_path = Path(out) if out is not None else None
    ckpt_path = Path(checkpoint) if checkpoint else (out_path.with_suffix(".ckpt.pt") if out_path else None)

    targets, masks = (t.to(device) for t in _targets(ds.train, config.background))
    n_views = len(ds.train)
    stage = dict.fromkeys(STAGES, 0.0)

    def clock() -> float:  # on a GPU the kernels run asynchronously: wait for them, so each stage is timed
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)
        return time.perf_counter()

    t_start = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=config.iterations, initial=start, desc=f"train {config.variant}", unit="it", file=log)
    running_loss, running_psnr = [], []
    frozen = None
    end = config.iterations if stop_at is None else max(start, min(stop_at, config.iterations))
    with heap_kept():
        for it in range(start, end):
            geometry_on = it >= config.geometry_frozen_iters
            model.set_geometry_trainable(geometry_on)
            factor = _lr_factor(config, it)
            for g in optimizer.param_groups:
                decays = g["name"] in ("mlp", "codebook", "sh")
                g["lr"] = base_lr[g["name"]] * (factor if decays else 1.0)
                if g["name"] in ("uv", "delta") and not geometry_on:
                    g["lr"] = 0.0
            v = view_at(config.seed, it, n_views)
            tau = tau_at(config, it)

            t0 = clock()
            if geometry_on:
                frozen = None
            elif frozen is None:  # frozen geometry: the Gaussians' positions are computed once
                with torch.no_grad():
                    frozen = model.gaussian_geometry()
            means, quats, scales = frozen if frozen is not None else model.gaussian_geometry()
            sh = model.sh_source("gumbel", tau)  # the native backend runs it for the Gaussians it shows only
            t1 = clock()
            out_img = render(means, quats, scales, model.gaussian_opacities(), sh, ds.train[v].camera,
                             tuple(config.background))
            t2 = clock()
            loss = (losses.image_loss(out_img.rgb, targets[v], config.lambda_dssim)
                    + config.lambda_alpha * losses.l1(out_img.alpha, masks[v])
                    + config.lambda_opacity_smooth * losses.opacity_smoothness(model.opacities(),
                                                                                    model.real_segments))
            t3 = clock()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            t4 = clock()
            optimizer.step()
            t5 = clock()
            for name, dt in zip(STAGES, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4), strict=True):
                stage[name] += dt
            if not torch.isfinite(loss.detach()):
                raise TrainError(f"the loss became {float(loss.detach())} at iteration {it}; lower the learning rates")
            running_loss.append(float(loss.detach()))
            running_psnr.append(losses.psnr(out_img.rgb, targets[v]))
            if (it + 1) % config.log_every == 0 or it + 1 == config.iterations:
                rec = {"iteration": it + 1, "loss": float(np.mean(running_loss)), "psnr": float(np.mean(running_psnr)),
                       "tau": tau}
                history.append(rec)
                running_loss, running_psnr = [], []
                if bar is not None:
                    bar.set_postfix(loss=f"{rec['loss']:.4f}", psnr=f"{rec['psnr']:.2f}")
            if bar is not None:
                bar.update(1)
            if ckpt_path is not None and (it + 1) % config.checkpoint_every == 0:
                save_checkpoint(ckpt_path, model=model, optimizer=optimizer, config=config, base=base,
                                iteration=it + 1, history=history, dataset=dataset_name,
                                seconds=seconds_before + time.perf_counter() - t_start)
    if bar is not None:
        bar.close()
    seconds = time.perf_counter() - t_start
    iterations_run = end - start
    if ckpt_path is not None:
        save_checkpoint(ckpt_path, model=model, optimizer=optimizer, config=config, base=base,
                        iteration=end, history=history, dataset=dataset_name, seconds=seconds_before + seconds)

    result = TrainResult(model, base, config, history=history, seconds=seconds, stage_seconds=stage,
                         iterations_run=iterations_run, out_path=out_path, backend=backend)
    if end < config.iterations:
        return result
    negligible, budget, t0 = None, None, time.perf_counter()  # (an export step, not one of the iterations' stages)
    if (model.export_refusal() is None and out_path is not None and config.opacity_budget > 0
            and not get_profile(profile).lossless):  # (the marks rest on geometry and opacity: either mode's)
        negligible, budget = negligible_segments(model.to_asset(base), ds.train, config.opacity_budget, backend,
                                                 dev), config.opacity_budget
    marked_seconds = time.perf_counter() - t0
    asset, mode, scores, report = choose_export(model, base, ds.train, config, profile, dev, backend, negligible,
                                                budget)  # scores: the files as written, marks and all
    result.asset, result.weight_mode, result.export_psnr = asset, mode, scores
    summary = {
        "config": config.to_dict(), "dataset": dataset_name, "backend": backend, "iterations_run": iterations_run,
        "seconds": round(seconds, 3), "seconds_total": round(seconds_before + seconds, 3),
        "stage_seconds": {k: round(v, 3) for k, v in stage.items()},
        "final": history[-1] if history else None, "weight_mode": mode, "export_psnr": scores,
        "appearance_parameters": model.appearance_parameters(), "gaussians": model.n_gaussians,
        # the opacities the writer lowered: none where the plain stream coded smaller
        "negligible_segments": None if negligible is None else report.opacity.marked if report.opacity.kept else 0,
        "negligible_seconds": round(marked_seconds, 3),
    }
    if asset is not None:
        asset.metadata["training"] = summary
    if out_path is not None:
        out_path.parent.mkdir(parents=True, exist_ok=True)
        write_text(out_path.with_suffix(".train.json"), json.dumps(summary, indent=2) + "\n")
        if asset is not None:
            from cghair_format import write

            write(asset, out_path, profile, negligible=negligible, opacity_budget=budget)
    return result
