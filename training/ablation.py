"""Reproduce the paper's ablation table and its codebook sweeps: PSNR / SSIM / LPIPS on held-out views,
appearance size and ratio.

    python -m training.ablation --strands ../shared/data/hair/Ratboy_mohawk.tfx --work ablation_out \
        --iters 1000 --views 32 --res 128 [--engine cycles|splat] [--variants latents,unique,...]
    cgh ablation ... --sweep K=10,30,60,90 [--sweep D=32,64,128,256] [--sweep N_T=16,32,64,96]

Renders the dataset once (Cycles by default; ``--engine splat`` when bpy is missing, and the
table says so), builds the cards once, trains every variant from the same cards with the same
schedule, and prints one table row per variant; ``ablation.json`` keeps everything and
``ablation.png`` plots PSNR against appearance size next to the paper's points and
``ablation_curves.png`` each variant's training-view PSNR against the iteration (the table's last column:
how much it still rose over the last tenth of the run, near 0 once it has flattened). ``--sweep`` instead
trains the latents variant at each value of K (codebook size), D (latent size) or N_T (card groups;
N_T = --n-cards is one group per card), into ``sweep_<key>.json`` and ``sweep_<key>.png``. Each JSON
is rewritten after every finished row, and a rerun with the same --work and settings skips the rows
it holds, so a long run that stops resumes. Quality is measured from the torch model (the free-SH
variants have no .cgh); for the variants with a .cgh the written file's figures are added.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from cghair_format.atomic import write_text
from cghair_format.cli.argtypes import int_at_least
from cghair_format.errors import CghError

from .cli_train import FROZEN_FRACTION, add_backend_argument
from .config import VARIANTS, ConfigError, TrainConfig

PAPER_NOTE = ("paper (CGHair, CVPR 2026, as quoted in our brief): latents within 1.6 dB PSNR of unique, "
              "with appearance parameters >= 200 x smaller")
# The paper's appearance ablation on its synthetic multi-tone hairstyle (../shared/PAPER.md, "Ablation of
# the appearance model"): variant -> (PSNR dB, appearance MB, read as 10^6 bytes). Reference figures on
# the paper's data, not measurements of ours.
PAPER_ABLATION: dict[str, tuple[float, float]] = {
    "unique": (33.99, 163.7),
    "multi-sh": (33.50, 11.95),
    "latents": (32.40, 0.71),
    "single-sh": (30.48, 0.46),
    "no-card-clustering": (28.00, 22.42),
}
# The paper's codebook sweeps of its latents variant, same data (../shared/PAPER.md, "Codebook sweeps"):
# key -> value -> (PSNR dB, size MB); the other two at K = 10, D = 64, N_T = 64; N_T = 400 is one group
# per card of its 400. Reference figures on the paper's data, not measurements of ours.
PAPER_SWEEPS: dict[str, dict[int, tuple[float, float]]] = {
    "K": {10: (32.40, 0.71), 30: (32.40, 1.72), 60: (32.36, 3.22), 90: (32.10, 4.72)},
    "D": {32: (32.39, 0.60), 64: (32.40, 0.71), 128: (32.18, 0.93), 256: (31.94, 1.37)},
    "N_T": {16: (31.49, 0.60), 32: (31.84, 0.64), 64: (32.40, 0.71), 96: (32.57, 0.79), 400: (33.04, 1.53)},
}
CHECKPOINT_EVERY = 250  # iterations: 5-10 minutes of a paper-scale variant on 2 cores, a few seconds to write
SWEEP_FIELDS = {"K": "codebook_size", "D": "latent_dim", "N_T": "n_groups"}  # sweep key -> TrainConfig field


def scaled_config(variant: str, iters: int, **overrides) -> TrainConfig:
    """The paper's config for a shorter run: the schedules (geometry freeze, temperature, decay)
    keep their proportions. Checkpointed every :data:`CHECKPOINT_EVERY` iterations, so that a stopped
    run resumes inside its variant."""
    cfg = TrainConfig(variant=variant, iterations=iters, geometry_frozen_iters=round(FROZEN_FRACTION * iters),
                      checkpoint_every=max(1, min(iters, CHECKPOINT_EVERY)), log_every=max(1, iters // 20))
    for key, value in overrides.items():
        setattr(cfg, key, value)
    return cfg.validate()


def parse_sweep(text: str) -> tuple[str, list[int]]:
    """``"K=10,30,60"`` -> ``("K", [10, 30, 60])``; a :class:`ConfigError` names what is wrong."""
    key, sep, values = text.partition("=")
    key = {k.upper(): k for k in SWEEP_FIELDS}.get(key.strip().upper())
    if not sep or key is None:
        raise ConfigError(f"--sweep {text!r}: give KEY=V1,V2,... with KEY one of {', '.join(SWEEP_FIELDS)}")
    try:
        ints = [int(v) for v in values.split(",")]
    except ValueError:
        raise ConfigError(f"--sweep {text!r}: values must be integers separated by commas") from None
    if len(set(ints)) != len(ints):
        raise ConfigError(f"--sweep {text!r}: a value is repeated")
    return key, ints


def check_sweep(key: str, values: list[int], iters: int, n_cards: int, points: int) -> None:
    """Refuse, before any long work, values the latents model cannot take (:class:`ConfigError`)."""
    for value in values:
        try:
            scaled_config("latents", iters, n_cards=n_cards, points_per_strand=points, **{SWEEP_FIELDS[key]: value})
        except ConfigError as exc:
            raise ConfigError(f"--sweep {key}={value}: {exc}") from None
        if key == "N_T" and value > n_cards:
            raise ConfigError(f"--sweep N_T={value}: more card groups than cards ({n_cards}); "
                              f"give --n-cards {value} or more (N_T = cards is one group per card)")


@dataclass
class Setup:
    """What every row of one run shares: the data, the cards' size and the schedule."""
    strands_path: str
    work: Path
    iters: int
    views: int
    res: int
    engine: str
    samples: int
    threads: int | None
    n_cards: int
    points: int
    dataset: Path | None = None
    log: TextIO = field(default_factory=lambda: sys.stderr)
    device: str = "cpu"
    backend: str | None = None

    def settings(self) -> dict:
        """The settings a row depends on: a rerun resumes rows only where these match (a given dataset's
        views are its own: the rendering settings are not recorded with it)."""
        rendering = {} if self.dataset else {"engine": self.engine, "views": self.views, "res": self.res}
        return {"strands": self.strands_path, **rendering, "backend": self.backend, "iterations": self.iters,
                "n_cards": self.n_cards, "points": self.points, "dataset": str(self.dataset) if self.dataset else None}

    @property
    def held_out(self) -> str:
        return held_out_views(self.dataset, self.engine, self.views, self.res)


def held_out_views(dataset: Path | None, engine: str, views: int, res: int) -> str:
    """Which views the rows are scored on, for tables and plots."""
    if dataset:
        return f"the held-out views of {dataset}"
    return f"{engine}-rendered held-out views ({views} views of {res} px)"


class RowFile:
    """The JSON of a run's rows, rewritten (atomically) after every finished row, so an interrupted run
    keeps them and a rerun with the same settings skips them. Runs side by side in one folder, each
    with its own variants or values, keep each other's rows: each reads the file again before it writes."""

    def __init__(self, path: Path, settings: dict, key: str, log: TextIO):
        self.path, self.settings, self.key = path, settings, key
        self.rows: list[dict] = []
        self.refresh()
        if self.rows:
            print(f"resuming {path}: rows already there, not trained again: {key} "
                  + ", ".join(str(r[key]) for r in self.rows), file=log)

    def refresh(self) -> None:
        """Take in the rows another run has written to the file since (a :class:`ConfigError` where the
        file is not JSON or holds another run's settings)."""
        if not self.path.is_file():
            return
        try:
            data = json.loads(self.path.read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{self.path} is not valid JSON ({exc}); give another --work or remove it") from None
        old = {k: data.get(k) for k in self.settings}
        if old != self.settings:
            diff = ", ".join(f"{k} {old[k]!r} there, {v!r} now" for k, v in self.settings.items() if old[k] != v)
            raise ConfigError(f"{self.path} holds rows of another run ({diff}); give another --work or remove it")
        held = {r[self.key] for r in self.rows}
        self.rows += [r for r in data["rows"] if r[self.key] not in held]

    def done(self, value) -> bool:
        """Whether the file holds ``value``'s row, this run's or one beside it."""
        self.refresh()
        return any(r[self.key] == value for r in self.rows)

    def add(self, row: dict, **extra) -> None:
        self.refresh()
        self.rows.append(row)
        self.save(**extra)

    def save(self, **extra) -> None:
        write_text(self.path, json.dumps({**self.settings, **extra, "rows": self.rows}, indent=2) + "\n")


def _start(setup: Setup, name: str, key: str, **settings):
    """Check what can fail early (LPIPS weights, the backend, rows of other settings in ``<work>/<name>``),
    then render the dataset once (kept in the work folder) or read the one given: the row record,
    the strands and the dataset."""
    import torch

    from cghair_format.exchange import load_strands

    from .backends import resolve_backend
    from .datasets.read import read_dataset
    from .datasets.synthetic import render_dataset
    from .lpips import Lpips

    if setup.threads:
        torch.set_num_threads(setup.threads)
    Lpips("alex")  # missing LPIPS weights fail now, not after the first row's training
    setup.backend = resolve_backend(setup.backend, setup.device)
    record = RowFile(setup.work / name, {**settings, **setup.settings()}, key, setup.log)
    strands = load_strands(setup.strands_path)
    setup.work.mkdir(parents=True, exist_ok=True)
    if setup.dataset is not None:  # a given dataset is read as it is, never rendered into
        return record, strands, read_dataset(setup.dataset)
    ds_dir = setup.work / f"dataset_{setup.engine}"
    if not (ds_dir / "transforms_test.json").is_file():
        t = time.perf_counter()
        render_dataset(strands, ds_dir, views=setup.views, res=setup.res, engine=setup.engine, samples=setup.samples,
                       progress=True, device=setup.device, backend=setup.backend)
        print(f"rendered {setup.views} views with {setup.engine} in {time.perf_counter() - t:.1f} s", file=setup.log)
    return record, strands, read_dataset(ds_dir)


def _trained_model(ckpt: Path, cfg: TrainConfig, ds, device: str):
    """The model and history of a finished run from its final checkpoint, or None where the run did not
    finish."""
    from cghair_format import decode

    from .model import HairModel
    from .train import load_checkpoint, mean_hair_colour

    if not ckpt.is_file():
        return None
    state = load_checkpoint(ckpt)
    if state["iteration"] != cfg.iterations:
        return None
    model = HairModel(decode(state["base_cgh"]), TrainConfig.from_dict(state["config"]), mean_hair_colour(ds.train))
    model.load_state_dict(state["model"])
    return model.to(device), state["history"]


def _resumable(ckpt: Path, cfg: TrainConfig) -> int | None:
    """The iteration of ``ckpt`` where it is a checkpoint of this very run (the same config, in a work
    folder whose settings :class:`RowFile` has checked); None where there is none or it is another's."""
    from .train import load_checkpoint

    if not ckpt.is_file():
        return None
    try:
        state = load_checkpoint(ckpt)
    except CghError:
        return None  # unreadable: trained again from the start
    return int(state["iteration"]) if state["config"] == cfg.to_dict() else None


def train_row(ds, base, cfg: TrainConfig, name: str, setup: Setup) -> dict:
    """Train ``cfg`` from ``base``'s cards, write ``<work>/<name>.cgh`` where the variant has an encoding,
    and measure it on the held-out views. A failure after training (the export, the written file's
    evaluation) is kept in the row (``export_error``, ``file_error``) with the model's figures."""
    from .evaluate import evaluate, evaluate_model
    from .model import tau_at
    from .train import train

    out = setup.work / f"{name}.cgh"
    ckpt = out.with_suffix(".ckpt.pt")
    resume = _resumable(ckpt, cfg)
    if resume is None:
        ckpt.unlink(missing_ok=True)  # a stale checkpoint must not pass for this run's
    else:
        print(f"{name}: resuming {ckpt} at iteration {resume} of {cfg.iterations}", file=setup.log)
    row: dict = {}
    try:
        result = train(ds, cards=base if resume is None else None, out=out, config=cfg,
                       resume=None if resume is None else ckpt,
                       progress=True, log=setup.log, device=setup.device, backend=setup.backend)
        model, mode, asset, seconds = result.model, result.weight_mode, result.asset, result.seconds
        history = result.history
    except Exception as exc:  # noqa: BLE001 - whatever failed, a finished training is kept
        trained = _trained_model(ckpt, cfg, ds, setup.device)
        if trained is None:
            raise
        model, history = trained
        row["export_error"] = f"{type(exc).__name__}: {exc}"
        print(f"{name}: trained, but {row['export_error']}; the row keeps the model's figures", file=setup.log)
        mode, asset, seconds = None, None, None
    tau = tau_at(cfg, cfg.iterations)
    ev = evaluate_model(model, ds.test, mode or "soft", tau, out_dir=setup.work / f"{name}_test", use_lpips=True,
                        backend=setup.backend)
    row.update(psnr=ev.psnr, ssim=ev.ssim, lpips=ev.lpips, appearance_bytes=model.appearance_bytes(),
               groups=model.n_groups, seconds=seconds, iterations=cfg.iterations, weight_mode=mode,
               train_psnr=history[-1]["psnr"] if history else None,
               history=[[h["iteration"], h["psnr"]] for h in history])
    if asset is not None:
        try:
            fev = evaluate(out, ds, use_lpips=False, device=setup.device, backend=setup.backend)
            row.update(file_psnr=fev.psnr, file_ssim=fev.ssim, file_bytes=out.stat().st_size)
        except Exception as exc:  # noqa: BLE001 - the model's figures stand without the file's
            row["file_error"] = f"{type(exc).__name__}: {exc}"
            print(f"{name}: evaluating {out} failed: {row['file_error']}", file=setup.log)
    lp = f", LPIPS {ev.lpips:.4f}" if ev.lpips is not None else ""
    print(f"{name}: test PSNR {ev.psnr:.2f} dB, SSIM {ev.ssim:.4f}{lp}", file=setup.log)
    return row


def run_ablation(strands_path: str, work: Path, iters: int, views: int, res: int, engine: str,
                 variants: list[str], samples: int, threads: int | None, n_cards: int, points: int,
                 dataset: Path | None = None, log: TextIO | None = None, device: str = "cpu",
                 backend: str | None = None) -> list[dict]:
    """Train each of ``variants`` from the same cards; rows go to ``<work>/ablation.json`` as they finish
    (a rerun with the same settings skips those there) and the plot to ``<work>/ablation.png``. Returns,
    plots and prints every row of the folder, earlier calls' included."""
    from .plot import COLOURS, plot_ablation, plot_curves
    from .train import base_asset

    log = log if log is not None else sys.stderr
    setup = Setup(strands_path, work, iters, views, res, engine, samples, threads, n_cards, points, dataset, log,
                  device, backend)
    record, strands, ds = _start(setup, "ablation.json", "variant")
    latents = scaled_config("latents", iters, n_cards=n_cards, points_per_strand=points)
    base = base_asset(latents, strands, progress=False)
    sizes = {"gaussians": base.n_gaussians, "strands_count": base.n_strands}
    for variant in variants:
        if not record.done(variant):
            cfg = scaled_config(variant, iters, n_cards=n_cards, points_per_strand=points)
            record.add({"variant": variant, **train_row(ds, base, cfg, variant, setup)}, **sizes)
    record.refresh()
    rows = record.rows  # with those of earlier calls on the same folder (other --variants)
    unique = next((r for r in record.rows if r["variant"] == "unique"), None)
    for r in record.rows:
        r["ratio_vs_unique"] = unique["appearance_bytes"] / r["appearance_bytes"] if unique else None
    record.save(**sizes)
    plot_ablation(rows, PAPER_ABLATION, work / "ablation.png",
                  f"{base.n_strands} strands, {iters} iterations, {setup.held_out}")
    curves = {r["variant"]: r["history"] for r in rows if r.get("history")}
    if curves:  # rows recorded before the histories were kept have none
        plot_curves(curves, COLOURS, work / "ablation_curves.png",
                    f"{base.n_strands} strands: training-view PSNR, mean of each {latents.log_every} iterations")
    return rows


def run_sweep(strands_path: str, work: Path, key: str, values: list[int], iters: int, views: int, res: int,
              engine: str, samples: int, threads: int | None, n_cards: int, points: int,
              dataset: Path | None = None, log: TextIO | None = None, device: str = "cpu",
              backend: str | None = None) -> list[dict]:
    """Train the latents variant at each of ``values`` of ``key`` (K, D or N_T), the rest at the paper's
    configuration, from the same cards (N_T regroups them) and dataset; rows go to
    ``<work>/sweep_<key>.json`` as they finish (a rerun skips those there), the plot to ``sweep_<key>.png``.
    Returns and plots every row of the folder's sweep of ``key``, earlier calls' included."""
    from .plot import plot_sweep
    from .train import base_asset

    check_sweep(key, values, iters, n_cards, points)
    log = log if log is not None else sys.stderr
    setup = Setup(strands_path, work, iters, views, res, engine, samples, threads, n_cards, points, dataset, log,
                  device, backend)
    record, strands, ds = _start(setup, f"sweep_{key}.json", "value", param=key)
    bases: dict[int, object] = {}  # card groups -> cards: only N_T rebuilds them
    for value in values:
        if record.done(value):
            continue
        cfg = scaled_config("latents", iters, n_cards=n_cards, points_per_strand=points,
                            **{SWEEP_FIELDS[key]: value})
        if cfg.n_groups not in bases:
            bases[cfg.n_groups] = base_asset(cfg, strands, progress=False)
        row = {"param": key, "value": value, **train_row(ds, bases[cfg.n_groups], cfg, f"{key}_{value}", setup)}
        if key == "N_T" and row["groups"] != value:
            print(f"N_T={value}: the cards hold {row['groups']} groups (capped at the strand count)", file=log)
        record.add(row)
    record.refresh()
    rows = sorted(record.rows, key=lambda r: r["value"])  # with those of earlier calls on the same folder
    plot_sweep(key, rows, PAPER_SWEEPS[key], work / f"sweep_{key}.png",
               f"{key} sweep (latents), {iters} iterations, {setup.held_out}")
    return rows


def late_rise(history: list[list[float]]) -> float | None:
    """How much the logged training-view PSNR rose over the last tenth of the run: the last figure less the
    one logged a tenth of the iterations before it (None without a history that long). Near 0 where
    the training has flattened."""
    if not history:
        return None
    last_it, last = history[-1]
    earlier = [psnr for it, psnr in history if it <= 0.9 * last_it]
    return last - earlier[-1] if earlier else None


def _file_psnr(row: dict, missing: str) -> str:
    """The written file's PSNR cell: the figure, else why there is none (its error, or ``missing``)."""
    if "file_psnr" in row:
        return f"{row['file_psnr']:.2f}"
    return row.get("file_error", row.get("export_error", missing))


def table(rows: list[dict], held_out: str) -> str:
    lines = [f"ablation on {held_out}",
             "| variant | PSNR (dB) | SSIM | LPIPS | appearance | ratio vs unique | .cgh PSNR | .cgh size "
             "| train PSNR (rise, last 10 %) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f"{r['ratio_vs_unique']:.1f} x" if r.get("ratio_vs_unique") else "-"
        fp = _file_psnr(r, "n/a (no .cgh encoding)")
        fb = f"{r['file_bytes'] / 1024:.0f} KiB" if "file_bytes" in r else "-"
        lp = f"{r['lpips']:.4f}" if r.get("lpips") is not None else "-"
        rise = late_rise(r.get("history"))
        tp = "-" if r.get("train_psnr") is None else f"{r['train_psnr']:.2f}" + (
            "" if rise is None else f" ({rise:+.2f})")
        lines.append(f"| {r['variant']} | {r['psnr']:.2f} | {r['ssim']:.4f} | {lp} | "
                     f"{r['appearance_bytes'] / 1024:.0f} KiB | {ratio} | {fp} | {fb} | {tp} |")
    lines.append(PAPER_NOTE)
    lines.append("paper's table (its data): " + ", ".join(f"{v} {psnr:.2f} dB / {mb:g} MB"
                                                          for v, (psnr, mb) in PAPER_ABLATION.items()))
    return "\n".join(lines)


def sweep_table(key: str, rows: list[dict], held_out: str) -> str:
    paper = PAPER_SWEEPS[key]
    lines = [f"{key} sweep of the latents variant ({SWEEP_FIELDS[key]}) on {held_out}",
             f"| {key} | PSNR (dB) | SSIM | LPIPS | appearance | .cgh PSNR | .cgh size | paper PSNR | paper size |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lp = f"{r['lpips']:.4f}" if r.get("lpips") is not None else "-"
        fp = _file_psnr(r, "-")
        fb = f"{r['file_bytes']:,} B" if "file_bytes" in r else "-"
        pp, pmb = (f"{paper[r['value']][0]:.2f}", f"{paper[r['value']][1]:g} MB") if r["value"] in paper else ("-", "-")
        lines.append(f"| {r['value']} | {r['psnr']:.2f} | {r['ssim']:.4f} | {lp} | {r['appearance_bytes']:,} B | "
                     f"{fp} | {fb} | {pp} | {pmb} |")
    lines.append("paper columns: its own sweep on its data (../shared/PAPER.md), not a measurement of ours")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--strands", required=True, help="a real hair model, e.g. ../shared/data/hair/Ratboy_mohawk.tfx")
    p.add_argument("--work", default="ablation_out", help="output folder (dataset, .cgh files, ablation.json); "
                   "a rerun with the same folder and settings skips the rows already there")
    p.add_argument("--iters", type=int_at_least(1), default=1000,
                   help="iterations per row (default: 1000; the schedules keep the paper's proportions)")
    p.add_argument("--views", type=int_at_least(2), default=32, help="views to render (default: 32)")
    p.add_argument("--res", type=int_at_least(8), default=128, help="view size in pixels (default: 128)")
    p.add_argument("--engine", choices=("cycles", "splat"), default="cycles",
                   help="ground truth renderer (default: cycles, needs bpy)")
    p.add_argument("--dataset", default=None, help="use this rendered dataset instead of rendering one")
    p.add_argument("--samples", type=int_at_least(1), default=32, help="Cycles samples (default: 32)")
    p.add_argument("--variants", default=",".join(VARIANTS), help=f"comma-separated (default: {','.join(VARIANTS)})")
    p.add_argument("--sweep", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="instead of the variants, train latents at each value of K (codebook size), D (latent size) "
                   "or N_T (card groups, at most --n-cards); repeat for several sweeps; the paper's: K=10,30,60,90, "
                   "D=32,64,128,256, N_T=16,32,64,96,400 (400 with --n-cards 400: one group per card)")
    p.add_argument("--n-cards", type=int_at_least(1), default=800, help="cards to build (default: 800)")
    p.add_argument("--points", type=int_at_least(4), default=32, help="points per strand (default: 32)")
    p.add_argument("--threads", type=int_at_least(1), default=None,
                   help="torch CPU threads (default: torch's choice; 1 is faster on a busy machine)")
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda (default: cpu)")
    add_backend_argument(p)


def run(args: argparse.Namespace) -> int:
    """Check every option, then run the sweeps (``--sweep``) or the variants; raises CghError on bad input."""
    variants = [v for v in args.variants.split(",") if v]
    bad = [v for v in variants if v not in VARIANTS]
    if bad or not variants:
        raise ConfigError(f"unknown variants {bad}; choose from {', '.join(VARIANTS)}")
    sweeps = [parse_sweep(text) for text in args.sweep]
    for key, values in sweeps:
        check_sweep(key, values, args.iters, args.n_cards, args.points)
    common = dict(iters=args.iters, views=args.views, res=args.res, engine=args.engine, samples=args.samples,
                  threads=args.threads, n_cards=args.n_cards, points=args.points,
                  dataset=Path(args.dataset) if args.dataset else None, device=args.device, backend=args.backend)
    held_out = held_out_views(common["dataset"], args.engine, args.views, args.res)
    for key, values in sweeps:
        print(sweep_table(key, run_sweep(args.strands, Path(args.work), key, values, **common), held_out))
    if not sweeps:
        print(table(run_ablation(args.strands, Path(args.work), variants=variants, **common), held_out))
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.ablation", description=__doc__.split("\n\n")[0])
    add_arguments(p)
    args = p.parse_args(argv)
    from cghair_format.errors import CghError

    try:
        return run(args)
    except CghError as exc:
        print(f"ablation: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
