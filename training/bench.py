"""Training speed on this machine, with a per-stage breakdown.

The small config (a real model of about 2,000 strands x 32 points, 128 x 128 views):

    python -m training.bench --strands ../shared/data/hair/Ratboy_mohawk.tfx --iters 2000 \
        [--backend reference|native|gsplat] [--threads 2] [--device cuda] [--json small.json]

The paper's scale (25,000 strands x 100 points densified from a real model exactly as
cghair_format/paper_scale.py gives, 800 cards, N_T 64, K 10, D 64, SH degree 3, 256 x 256 views):

    python -m training.bench --paper-scale [--strands ../shared/data/hair/harolongo.data] \
        --iters 20 [--reference-iters 2] [--res 256] [--backend ...] [--json paper.json]

Renders a splat dataset into the work folder if it has none, builds the cards (timed apart; cached
in the work folder at paper scale; the work folder is ``~/.cache/cghair/bench`` unless ``--work``
or ``$CGH_BENCH_DIR`` moves it, so no cache lands in the repository), trains the latents variant
and prints iterations per second, milliseconds per stage, peak memory (resident set; on CUDA also
the GPU's peak allocation) and the GPU's name. The small config then evaluates the written .cgh on
the held-out views; the paper scale trains the first N of N + 1 scheduled iterations (so nothing
is exported) and then a few iterations of the ``reference`` backend on the same scene, for the
speed-up. ``--json`` writes every figure. It reports figures only; it asserts nothing about time.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

from cghair_format.errors import CghError

from .cli_train import add_backend_argument

REPO = Path(__file__).resolve().parents[1]
PAPER_SCALE_DEFAULT_MODEL = "harolongo.data"
DEFAULTS = {  # (small config, paper scale)
    "iters": (2000, 20), "views": (32, 8), "res": (128, 256),
}


class BenchError(CghError, ValueError):
    """The benchmark cannot run with these arguments."""


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--strands", default=None, help="a real hair model (required for the small config; at paper "
                   f"scale default ../shared/data/hair/{PAPER_SCALE_DEFAULT_MODEL})")
    p.add_argument("--paper-scale", action="store_true",
                   help="25,000 strands x 100 points, 800 cards, N_T 64, K 10, D 64, SH 3 "
                        "(cghair_format/paper_scale.py)")
    p.add_argument("--work", default=None, help="folder for the dataset, cards and outputs, kept between runs "
                   "(default: $CGH_BENCH_DIR, else ~/.cache/cghair/bench, outside the repository)")
    p.add_argument("--iters", type=int, default=None, help="training iterations (default: 2000; paper scale 20)")
    p.add_argument("--reference-iters", type=int, default=2,
                   help="paper scale: iterations of the reference backend for the speed-up (default 2; 0 skips "
                        "them; the reference needs more than 9.5 GiB there at 128 x 128 and above)")
    p.add_argument("--views", type=int, default=None, help="dataset views (default: 32; paper scale 8)")
    p.add_argument("--res", type=int, default=None, help="view width and height (default: 128; paper scale 256)")
    p.add_argument("--points", type=int, default=32, help="points per strand of the small config (default 32)")
    p.add_argument("--n-cards", type=int, default=800, help="cards of the small config (default 800)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda (default: cpu)")
    add_backend_argument(p)
    p.add_argument("--engine", choices=("splat", "cycles"), default="splat", help="dataset renderer (default splat)")
    p.add_argument("--dataset", default=None, help="use this rendered dataset instead of rendering one")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures to FILE")
    args = p.parse_args(argv)
    scale = int(args.paper_scale)
    for name, values in DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, values[scale])
    if args.strands is None and not args.paper_scale:
        p.error("--strands is required (or give --paper-scale)")
    try:
        _run(args)
    except CghError as exc:
        print(f"bench: error: {exc}", file=sys.stderr)
        return 2
    return 0


def _emit(report: dict, args: argparse.Namespace, lines: list[str]) -> None:
    """Print ``lines`` now and rewrite the JSON, so that a run stopped later keeps what it measured."""
    report["machine"]["load_average_now"] = os.getloadavg()[0]
    print("\n".join(lines), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2) + "\n")


def _peak_memory(device) -> dict:
    import torch

    out = {"peak_rss_gib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2)}
    if device.type == "cuda":
        out["cuda_peak_allocated_gib"] = round(torch.cuda.max_memory_allocated(device) / 2**30, 2)
    return out


def _train_run(ds_dir: Path, base, cfg, backend: str, device, out: Path | None, stop_at: int | None) -> dict:
    import torch

    from .train import train

    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    cpu = time.process_time()
    result = train(ds_dir, cards=base, out=out, config=cfg, progress=True, device=str(device), backend=backend,
                   stop_at=stop_at)
    n = max(1, result.iterations_run)
    cpu = time.process_time() - cpu
    stage_ms = {k: round(1000 * v / n, 1) for k, v in result.stage_seconds.items()}
    return {"backend": backend, "iterations": result.iterations_run, "seconds": round(result.seconds, 3),
            "iterations_per_second": round(result.iterations_run / max(result.seconds, 1e-9), 3),
            "ms_per_iteration": round(sum(stage_ms.values()), 1), "stage_ms_per_iteration": stage_ms,
            # all threads' CPU time over the whole train() call (set-up and any export included): less
            # sensitive than wall time to other processes on a shared machine
            "cpu_ms_per_iteration": round(1000 * cpu / n, 1),
            "geometry_frozen_iterations": min(cfg.geometry_frozen_iters, result.iterations_run),
            "final": result.history[-1] if result.history else None, **_peak_memory(device)}


def cache_dir() -> Path:
    """``$CGH_BENCH_DIR``, else ``$XDG_CACHE_HOME/cghair/bench`` (``~/.cache/cghair/bench``): the default work folder,
    outside the repository, where the cards and datasets are cached between runs."""
    if os.environ.get("CGH_BENCH_DIR"):
        return Path(os.environ["CGH_BENCH_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cghair" / "bench"


def _paper_scene(args: argparse.Namespace, work: Path):
    """The paper-scale strands, their cards (cached in ``work``), the config for N iterations and a tag."""
    from cghair_format import paper_scale as ps

    from .ablation import scaled_config
    from .train import base_asset

    path = Path(args.strands or REPO.parent / "shared" / "data" / "hair" / PAPER_SCALE_DEFAULT_MODEL)
    if not path.is_file():
        raise BenchError(f"hair model {path} not found (give --strands)")
    strands = ps.paper_scale_strands(path)

    def config(iters: int):
        return scaled_config("latents", iters, n_cards=ps.CARDS, n_groups=ps.GROUPS, points_per_strand=ps.POINTS,
                             codebook_size=ps.K, latent_dim=ps.D, mlp_hidden=[ps.HIDDEN], sh_degree=ps.SH_DEGREE)

    tag = f"{path.stem}_{ps.STRANDS}x{ps.POINTS}_{ps.CARDS}c{ps.GROUPS}g"
    cards_file = work / f"{tag}_cards.cgh"
    if cards_file.is_file():
        from cghair_format import read

        return strands, read(cards_file), config, tag
    from cghair_format import write

    base = base_asset(config(args.iters + 1), strands, progress=False)
    write(base, cards_file, "lossless")
    return strands, base, config, tag


def _small_scene(args: argparse.Namespace, work: Path):
    """The small config's strands, cards, config for N iterations and tag (nothing cached)."""
    from cghair_format.exchange import load_strands

    from .ablation import scaled_config
    from .train import base_asset

    strands = load_strands(args.strands)

    def config(iters: int):
        return scaled_config("latents", iters, n_cards=args.n_cards, points_per_strand=args.points)

    return strands, base_asset(config(args.iters), strands, progress=False), config, \
        f"{Path(args.strands).stem}_{args.points}p"


def _work_dir(args: argparse.Namespace) -> Path:
    work = Path(args.work) if args.work else cache_dir()
    try:
        work.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BenchError(f"cannot create the work folder {work} ({exc.strerror}); give another with --work") from None
    return work


def _run(args: argparse.Namespace) -> None:
    import torch

    from .backends import resolve_backend
    from .datasets.synthetic import render_dataset
    from .splatter import torch_device

    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch_device(args.device)
    backend = resolve_backend(args.backend, device)
    work = _work_dir(args)
    load_start = os.getloadavg()[0]
    t = time.perf_counter()
    strands, base, config, tag = (_paper_scene if args.paper_scale else _small_scene)(args, work)
    cards_s = time.perf_counter() - t
    ds_dir = Path(args.dataset) if args.dataset else work / f"dataset_{tag}_{args.engine}_{args.res}"
    t = time.perf_counter()
    rendered = not (ds_dir / "transforms_test.json").is_file()
    if rendered:
        render_dataset(strands, ds_dir, views=args.views, res=args.res, engine=args.engine, device=str(device),
                       backend=backend, progress=True)
    report = {
        "machine": {"cores": os.cpu_count(), "torch_threads": torch.get_num_threads(), "device": str(device),
                    "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None,
                    "load_average_start": load_start},
        "scene": {"model": args.strands or str(PAPER_SCALE_DEFAULT_MODEL), "paper_scale": args.paper_scale,
                  "strands": base.n_strands, "points": base.points_per_strand, "gaussians": base.n_gaussians,
                  "cards": base.cards.count, "views": args.views, "res": args.res, "engine": args.engine},
        "work": str(work), "cards_seconds": round(cards_s, 2),
        "dataset_seconds": round(time.perf_counter() - t, 2) if rendered else None,
    }
    _emit(report, args, _header_lines(report))
    if args.paper_scale:
        _paper_runs(report, args, ds_dir, base, config, backend, device)
    else:
        _small_run(report, args, ds_dir, base, config(args.iters), backend, device, work / f"{tag}_{backend}.cgh")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


def _header_lines(report: dict) -> list[str]:
    m, s = report["machine"], report["scene"]
    gpu = f", {m['gpu']}" if m["gpu"] else ""
    dataset = f"; dataset: {report['dataset_seconds']:.1f} s" if report["dataset_seconds"] is not None else ""
    return [f"machine: {m['cores']} cores{gpu}, torch threads {m['torch_threads']}, load average at start "
            f"{m['load_average_start']:.2f}",
            f"scene: {s['strands']} strands x {s['points']} points = {s['gaussians']} Gaussians, {s['cards']} cards, "
            f"{s['views']} views at {s['res']} x {s['res']} ({s['engine']}); work folder {report['work']}",
            f"cards: {report['cards_seconds']:.1f} s{dataset}"]


def _paper_runs(report: dict, args, ds_dir: Path, base, config, backend: str, device) -> None:
    """The first N of N + 1 iterations (nothing exported), then a few of the reference for the speed-up."""
    report["run"] = _train_run(ds_dir, base, config(args.iters + 1), backend, device, None, args.iters)
    _emit(report, args, _run_lines("", report["run"]))
    if args.reference_iters > 0 and backend != "reference":
        ref = _train_run(ds_dir, base, config(args.reference_iters + 1), "reference", device, None,
                         args.reference_iters)
        report["reference"] = ref
        report["speedup_over_reference"] = round(ref["ms_per_iteration"] / report["run"]["ms_per_iteration"], 2)
        _emit(report, args, _run_lines("reference ", ref)
              + [f"speed-up over reference: {report['speedup_over_reference']:.1f} x"])


def _small_run(report: dict, args, ds_dir: Path, base, cfg, backend: str, device, out: Path) -> None:
    """The whole run, exported to ``out``, then its held-out scores."""
    from .evaluate import evaluate

    report["run"] = _train_run(ds_dir, base, cfg, backend, device, out, None)
    ev = evaluate(out, ds_dir, use_lpips=False, device=str(device), backend=backend)
    h = report["held_out"] = {"psnr": round(ev.psnr, 3), "ssim": round(ev.ssim, 4), "views": len(ev.per_view),
                              "ground_truth": args.engine}
    _emit(report, args, _run_lines("", report["run"]) + [
        f"held-out: PSNR {h['psnr']:.2f} dB, SSIM {h['ssim']:.4f} ({h['views']} views, {h['ground_truth']} "
        "ground truth)"])


def _run_lines(label: str, x: dict) -> list[str]:
    mem = f"peak RSS so far {x['peak_rss_gib']:.2f} GiB" + (
        f", CUDA peak {x['cuda_peak_allocated_gib']:.2f} GiB" if "cuda_peak_allocated_gib" in x else "")
    lines = [f"{label}backend {x['backend']}: {x['iterations']} iterations ({x['geometry_frozen_iterations']} with "
             f"frozen geometry) in {x['seconds']:.1f} s, {x['iterations_per_second']:.2f} it/s, "
             f"{x['ms_per_iteration']:.0f} ms/it ({x['cpu_ms_per_iteration']:.0f} ms of CPU time); {mem}"]
    total = max(x["ms_per_iteration"], 1e-9)
    lines += [f"  {name:<9}{ms:9.1f} ms/it  {100 * ms / total:5.1f} %"
              for name, ms in x["stage_ms_per_iteration"].items()]
    return lines


if __name__ == "__main__":
    sys.exit(main())
