"""``make gpu-check``: one run that proves the CUDA and NVIDIA paths on a GPU machine (issue 33).

    python3 tools/gpu_check.py [--out DIR] [--budget SECONDS] [--hair DIR] [--wheels DIR] [--python PY]
    python3 tools/gpu_check.py --dry-run [--out DIR]

From a fresh copy of the tree, with the machine's Python holding a CUDA build of torch and an NVIDIA
driver, the stages run in this order, each a subprocess with its own time limit (cut to what is left
of ``--budget``, 480 s by default), so one stuck stage still leaves the others' figures:

- ``install``: a virtual environment (``.venv-gpu``) that sees the machine's packages
  (``--system-site-packages``), so the machine's CUDA torch serves as it is; ``pip install -e
  '.[training,viewer,cuda,dev]'`` with torch constrained to that build (never the CPU pin of ``make
  venv``), then the Cython kernels built in place. ``--wheels DIR`` installs offline from DIR.
- ``environment``: GPU, driver, CUDA of torch, nvcc, Python and package versions.
- ``scene``: procedural strands for the small comparison scene (and for the paper scale when
  ``--hair`` has no harolongo.data).
- ``gsplat_kernels``: the first use of gsplat's CUDA kernels, timed: their compile on a first run,
  cached in ``~/.cache/cghair/torch_extensions`` (``TORCH_EXTENSIONS_DIR``) where a second run finds them.
- ``cuda_tests``: every CUDA test (junit counts; on a GPU machine a skip counts as not passed).
- ``train_gsplat``: ``python -m training.bench --paper-scale --device cuda --backend gsplat --res 512``:
  it/s, ms per stage, peak GPU memory.
- ``viewer``: ``cgh bench-viewer`` at the paper's scale (25,000 strands x 100 Gaussians) at 1920 x 1080,
  compute and raster rasterizers, full quality and the level-of-detail budgets, PSNR against the reference.
- ``train_native``, ``train_cuda``: a short training run on one small scene with the native backend on
  the CPU and with gsplat on CUDA; their held-out PSNRs must agree within 0.3 dB.
- ``train_reference``: a few iterations of the reference backend on CUDA at the paper's scale, for the
  speed-up of gsplat over it.

Everything goes to ``DIR/gpu_check.json`` (the machine, each stage's status, time and error, each
figure, the issue's targets) and ``DIR/summary.txt`` (also printed); each stage's output is in
``DIR/logs/``. ``tools/bench_tables.py docs/benchmarks.json -o docs/benchmarks.md --gpu
DIR/gpu_check.json`` puts the figures into the page's GPU section. ``--dry-run`` runs the same
stages here with tiny sizes and the CPU backends (native for gsplat, the reference, Mesa's llvmpipe
for the viewer) and installs nothing: CI runs it (tests/test_gpu_check.py). Exit status: 0 when
every stage passed, 1 when one failed, 2 on bad arguments.

This file needs only the standard library: it starts on the machine's Python before anything is installed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXTRAS = "training,viewer,cuda,dev"
DEFAULT_BUDGET_S = 480  # the 8 minutes of wall time
PSNR_TOLERANCE_DB = 0.3  # held-out PSNR of gsplat on CUDA against native on the CPU
TARGETS = {"gsplat_iterations_per_second": 50.0, "viewer_full_quality_fps": 200.0}  # issue 33, on an H100
CUDA_TESTS = ["tests/training/test_backends.py", "tests/training/test_cuda_training.py",
              "tests/training/test_splatter.py", "-k", "cuda or gsplat"]
PAPER_MODEL = "harolongo.data"


class CheckError(Exception):
    """The check cannot start with these arguments (exit 2)."""


@dataclass
class Stage:
    name: str
    commands: list[list[str]]  # run in turn under one time limit
    timeout_s: float
    figures: dict = field(default_factory=dict)  # filled from the stage's own output after it ran


def cache_root() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cghair"


# --- stages that run inside the checked environment (hidden subcommands) -------------------------------------


def _first_line(argv: list[str]) -> str | None:
    try:
        out = subprocess.run(argv, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    lines = [x.strip() for x in out.stdout.splitlines() if x.strip()]
    return (lines[-1] if argv[0] == "nvcc" else lines[0]) if out.returncode == 0 and lines else None


def probe() -> dict:
    """The machine: Python, packages, torch's CUDA, the GPU, the driver and nvcc."""
    from importlib import metadata

    info: dict = {"python": platform.python_version(), "platform": platform.platform(), "cores": os.cpu_count()}
    for pkg in ("cghair", "torch", "gsplat", "numpy", "moderngl"):
        try:
            info[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            info[pkg] = None
    try:
        import torch
    except ImportError:
        torch = None
    info["torch_cuda"] = torch.version.cuda if torch else None
    info["cuda_available"] = bool(torch and torch.cuda.is_available())
    if info["cuda_available"]:
        props = torch.cuda.get_device_properties(0)
        info.update(gpu=props.name, gpu_memory_gib=round(props.total_memory / 2**30, 1),
                    compute_capability=f"{props.major}.{props.minor}")
    smi = _first_line(["nvidia-smi", "--query-gpu=name,driver_version", "--format=csv,noheader"])
    info["driver"] = smi.split(",")[-1].strip() if smi else None
    info["nvcc"] = _first_line(["nvcc", "--version"])
    return info


def first_use(backend: str, device: str) -> dict:
    """The first use of a backend, timed: for gsplat, loading (on a first run compiling) its CUDA kernels."""
    import torch  # noqa: F401  (imported before the clock starts)

    ext = Path(os.environ.get("TORCH_EXTENSIONS_DIR", cache_root() / "torch_extensions"))
    cached = ext.is_dir() and any(ext.iterdir())
    t = time.perf_counter()
    from training.backends import check_backend

    check_backend(backend, device)
    return {"backend": backend, "device": device, "seconds": round(time.perf_counter() - t, 2),
            "extensions_dir": str(ext), "cache_found": cached}


def write_strands(path: str, n_strands: int, n_points: int) -> dict:
    """Procedural straight hair (cghair_format.synth), the same for a given size on every machine."""
    from cghair_format.exchange import save_strands
    from cghair_format.synth import synthesize

    save_strands(synthesize("straight", n_strands=n_strands, n_points=n_points, seed=0), path)
    return {"path": path, "strands": n_strands, "points": n_points}


def install(venv: Path, wheels: str | None) -> dict:
    """The environment over the machine's CUDA torch: a venv that sees its packages, torch pinned to it."""
    t = time.perf_counter()
    try:
        import torch
    except ImportError:
        raise CheckError(f"{sys.executable} has no torch: install a CUDA build of torch into the machine's "
                         "Python first (docs/install.md), or give --python") from None
    if not torch.cuda.is_available():
        raise CheckError(f"torch {torch.__version__} of {sys.executable} sees no CUDA device (a CPU build, or no "
                         "NVIDIA driver): install a CUDA build of torch (docs/install.md)")
    py = venv / "bin" / "python"
    if not py.exists():
        subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    constraints = venv / "constraints.txt"
    constraints.write_text(f"torch=={torch.__version__}\n")  # pip may not replace the machine's build
    pip = [str(py), "-m", "pip", "install", "-q", "-c", str(constraints)]
    if wheels:
        pip += ["--no-index", "--find-links", wheels]
    subprocess.run([*pip, "-e", f".[{EXTRAS}]"], check=True, cwd=REPO)
    subprocess.run([str(py), "setup.py", "build_ext", "--inplace"], check=True, cwd=REPO, stdout=subprocess.DEVNULL)
    return {"venv": str(venv), "torch": torch.__version__, "seconds": round(time.perf_counter() - t, 1)}


def _subcommand(argv: list[str]) -> int:
    """The stages' own steps, run by the checked environment's Python: probe, first-use, strands, install."""
    p = argparse.ArgumentParser(prog="gpu_check.py")
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("probe").add_argument("--json", required=True)
    use = sub.add_parser("first-use")
    use.add_argument("backend")
    use.add_argument("device")
    use.add_argument("--json", required=True)
    strands = sub.add_parser("strands")
    strands.add_argument("path")
    strands.add_argument("n_strands", type=int)
    strands.add_argument("n_points", type=int)
    inst = sub.add_parser("install")
    inst.add_argument("--venv", required=True)
    inst.add_argument("--wheels", default=None)
    a = p.parse_args(argv)
    try:
        if a.cmd == "probe":
            result, out = probe(), a.json
        elif a.cmd == "first-use":
            result, out = first_use(a.backend, a.device), a.json
        elif a.cmd == "strands":
            result, out = write_strands(a.path, a.n_strands, a.n_points), None
        else:
            result, out = install(Path(a.venv), a.wheels), None
    except CheckError as exc:
        print(f"gpu_check: {a.cmd}: error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # a stage's failure, whatever it is, is one line of its record (the log has the rest)
        print(f"gpu_check: {a.cmd}: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    if out:
        Path(out).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result))
    return 0


# --- the plan ------------------------------------------------------------------------------------------------

LIMITS_S = {"install": 240, "environment": 60, "scene": 60, "gsplat_kernels": 300, "cuda_tests": 180,
            "train_gsplat": 180, "viewer": 180, "train_native": 120, "train_cuda": 90, "train_reference": 120}
DRY_LIMIT_S = 90


def _scale_args(paper: Path, small: Path, dry: bool, iters: int) -> list[str]:
    """training.bench at the paper's scale at 512 x 512 (a dry run: the small config, tiny, as its recipe is fixed
    at 2.5 M Gaussians)."""
    if dry:
        return [*_small_args(small, dry), "--iters", "3"]
    return ["--paper-scale", "--strands", str(paper), "--iters", str(iters), "--res", "512", "--reference-iters", "0"]


def _small_args(small: Path, dry: bool) -> list[str]:
    """training.bench's small config on the procedural comparison scene."""
    if dry:
        return ["--strands", str(small), "--views", "2", "--res", "16", "--points", "6", "--n-cards", "8",
                "--threads", "1"]
    return ["--strands", str(small), "--views", "16", "--res", "64", "--points", "24", "--n-cards", "200"]


VIEWER_ARGS = ["--synthetic", "25000", "--points", "101", "--width", "1920", "--height", "1080", "--frames", "10"]
DRY_VIEWER_ARGS = ["--synthetic", "30", "--points", "6", "--width", "64", "--height", "36", "--frames", "1",
                   "--reference-size", "32", "18"]


def plan(args: argparse.Namespace, py: str, raw: Path, work: Path) -> list[Stage]:
    """The stages in order of what they are worth when the budget runs short."""
    dry = args.dry_run
    tool = [py, str(Path(__file__).resolve())]
    small = work / "small_strands.npz"
    paper = Path(args.hair) / PAPER_MODEL
    if not paper.is_file():
        paper = work / "procedural_strands.npz"
    device, fast = ("cpu", "native") if dry else ("cuda", "gsplat")
    compare = [*_small_args(small, dry), "--iters", "3" if dry else "300"]

    def stage(name: str, *commands: list[str]) -> Stage:
        return Stage(name, list(commands), min(LIMITS_S[name], DRY_LIMIT_S) if dry else LIMITS_S[name])

    def bench(name: str, scene: list[str], dev: str, backend: str) -> Stage:
        return stage(name, [py, "-m", "training.bench", *scene, "--device", dev, "--backend", backend, "--json",
                            str(raw / f"{name}.json")])

    scene = [[*tool, "strands", str(small), *(("60", "8") if dry else ("1500", "24"))]]
    if not dry and paper.parent == work:
        scene.append([*tool, "strands", str(paper), "8000", "21"])  # harolongo's size, densified as it would be
    install = [sys.executable, tool[1], "install", "--venv", str(args.venv),
               *(["--wheels", args.wheels] if args.wheels else [])]
    return [
        *([stage("install", install)] if not dry and args.python is None else []),
        stage("environment", [*tool, "probe", "--json", str(raw / "environment.json")]),
        stage("scene", *scene),
        stage("gsplat_kernels", [*tool, "first-use", fast, device, "--json", str(raw / "kernels.json")]),
        stage("cuda_tests", [py, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider",
                             f"--junitxml={raw / 'cuda_tests.xml'}", *CUDA_TESTS]),
        bench("train_gsplat", _scale_args(paper, small, dry, 100), device, fast),
        stage("viewer", [py, "-m", "cghair_format", "bench-viewer", *(DRY_VIEWER_ARGS if dry else VIEWER_ARGS),
                         "--json", str(raw / "viewer.json")]),
        bench("train_native", compare, "cpu", "native"),
        bench("train_cuda", compare, device, "reference" if dry else fast),
        bench("train_reference", _scale_args(paper, small, dry, 5), device, "reference"),
    ]


# --- running a stage -------------------------------------------------------------------------------------------


def _last_line(log: Path) -> str | None:
    lines = [x.strip() for x in log.read_text(errors="replace").splitlines() if x.strip()]
    return lines[-1][:500] if lines else None


def run_stage(stage: Stage, env: dict, log: Path, deadline: float) -> dict:
    """Run the stage's commands in turn within its limit (cut to the deadline); a stage past it is killed
    with all its processes, so nothing of it runs on into the next."""
    limit = min(stage.timeout_s, deadline - time.monotonic())
    rec = {"status": "skipped", "seconds": 0.0, "timeout_s": round(max(limit, 0.0), 1),
           "commands": [" ".join(c) for c in stage.commands], "log": str(log), "error": None}
    if limit < 1:
        rec["error"] = "no time left of the check's budget (--budget)"
        return rec
    start = time.monotonic()
    rec["status"] = "ok"
    with log.open("w") as f:
        for argv in stage.commands:
            f.write(f"$ {' '.join(argv)}\n")
            f.flush()
            try:
                proc = subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, env=env, cwd=REPO,
                                        start_new_session=True)
            except OSError as exc:
                rec.update(status="failed", error=f"cannot run {argv[0]}: {exc.strerror}")
                break
            try:
                code = proc.wait(timeout=max(0.1, start + limit - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                rec.update(status="timeout", error=f"stopped after its limit of {limit:.0f} s")
                break
            if code != 0:
                rec["status"] = "failed"
                break
    rec["seconds"] = round(time.monotonic() - start, 1)
    if rec["status"] == "failed" and rec["error"] is None:
        rec["error"] = _last_line(log)
    return rec


# --- figures ---------------------------------------------------------------------------------------------------


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _tests(path: Path) -> dict | None:
    """pytest's junit counts, and the tests that did not pass with their first line."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return None
    suite = root if root.tag == "testsuite" else root.find("testsuite")
    counts = {k: int(suite.get(k, 0)) for k in ("tests", "failures", "errors", "skipped")}
    not_passed = []
    for case in suite.iter("testcase"):
        for outcome in ("failure", "error", "skipped"):
            node = case.find(outcome)
            if node is not None:
                message = (node.get("message") or "").strip().splitlines()
                not_passed.append({"test": f"{case.get('classname')}::{case.get('name')}", "outcome": outcome,
                                   "message": message[0][:300] if message else ""})
    return {**counts, "passed": counts["tests"] - counts["failures"] - counts["errors"] - counts["skipped"],
            "not_passed": not_passed}


def _training(report: dict | None) -> dict | None:
    if not report or not report.get("run"):
        return None
    run = report["run"]
    keys = ("backend", "iterations", "iterations_per_second", "ms_per_iteration", "stage_ms_per_iteration",
            "cuda_peak_allocated_gib", "peak_rss_gib")
    return {"device": report["machine"]["device"], "scene": report["scene"], "cards_seconds": report["cards_seconds"],
            "dataset_seconds": report["dataset_seconds"], **{k: run.get(k) for k in keys},
            "held_out_psnr": report.get("held_out", {}).get("psnr")}


def _viewer(report: dict | None) -> dict | None:
    if not report or not report.get("runs"):
        return None
    runs = [{"rasterizer": r["rasterizer"], "budget": r["budget"], "gaussians_drawn": r["gaussians_drawn"],
             "frame_ms": round(1000 * r["frame_s"], 3), "fps": round(1 / max(r["frame_s"], 1e-9), 1),
             "psnr_vs_reference_db": r["psnr_vs_reference_db"], "psnr_vs_full_db": r["psnr_vs_full_db"]}
            for r in report["runs"]]
    return {**{k: v for k, v in report.items() if k != "runs"}, "runs": runs}


def figures(raw: Path) -> dict:
    """Every figure the stages left in ``raw``, whatever their status (a stopped bench keeps what it measured)."""
    out = {"gsplat_kernels": _read_json(raw / "kernels.json"), "cuda_tests": _tests(raw / "cuda_tests.xml"),
           "viewer": _viewer(_read_json(raw / "viewer.json"))}
    for name in ("train_gsplat", "train_reference", "train_native", "train_cuda"):
        out[name] = _training(_read_json(raw / f"{name}.json"))
    fast, ref = out["train_gsplat"], out["train_reference"]
    out["speedup_over_reference"] = (round(ref["ms_per_iteration"] / fast["ms_per_iteration"], 2)
                                     if fast and ref and fast["ms_per_iteration"] else None)
    native, cuda = out["train_native"], out["train_cuda"]
    if native and cuda and native["held_out_psnr"] is not None and cuda["held_out_psnr"] is not None:
        out["held_out_psnr_delta_db"] = round(cuda["held_out_psnr"] - native["held_out_psnr"], 3)
    else:
        out["held_out_psnr_delta_db"] = None
    return out


def targets(fig: dict, dry: bool) -> dict:
    """The issue's targets against the figures: met True/False, or None where unmeasured (a dry run's speeds
    are the CPU's, so it judges only the tests and the PSNR agreement)."""
    def row(measured, target, at_least=True, speed=False):
        met = None if measured is None or (dry and speed) else (measured >= target if at_least else measured <= target)
        return {"measured": measured, "target": target, "met": met}

    fast, viewer, tests = fig["train_gsplat"], fig["viewer"], fig["cuda_tests"]
    full = [r for r in (viewer or {}).get("runs", []) if r["rasterizer"] == "compute" and r["budget"] is None]
    delta = fig["held_out_psnr_delta_db"]
    return {
        "gsplat_iterations_per_second": row(fast and fast["iterations_per_second"],
                                            TARGETS["gsplat_iterations_per_second"], speed=True),
        "viewer_full_quality_fps": row(full[0]["fps"] if full else None, TARGETS["viewer_full_quality_fps"],
                                       speed=True),
        "held_out_psnr_delta_db": row(None if delta is None else abs(delta), PSNR_TOLERANCE_DB, at_least=False),
        # on a GPU machine a skipped CUDA test is a path left unproven; a dry run skips them all
        "cuda_tests_not_passed": row(None if tests is None else tests["failures"] + tests["errors"]
                                     + (0 if dry else tests["skipped"]), 0, at_least=False),
    }


# --- the report ------------------------------------------------------------------------------------------------


def _ms(stages: dict) -> str:
    return ", ".join(f"{k} {v:.1f}" for k, v in stages.items())


def _training_lines(fig: dict) -> list[str]:
    lines = []
    fast, ref = fig["train_gsplat"], fig["train_reference"]
    for label, x in (("training", fast), ("reference", ref)):
        if x:
            s = x["scene"]
            mem = (f"CUDA peak {x['cuda_peak_allocated_gib']:.2f} GiB" if x.get("cuda_peak_allocated_gib") is not None
                   else f"peak RSS {x['peak_rss_gib']:.2f} GiB")
            lines.append(f"{label}: {s['gaussians']:,} Gaussians at {s['res']} x {s['res']}, {x['backend']} on "
                         f"{x['device']}: {x['iterations_per_second']:.2f} it/s, {x['ms_per_iteration']:.1f} ms/it "
                         f"({_ms(x['stage_ms_per_iteration'])}), {mem}")
    if fig["speedup_over_reference"]:
        lines.append(f"speed-up over the reference: {fig['speedup_over_reference']:.1f} x")
    native, cuda = fig["train_native"], fig["train_cuda"]
    if native and cuda and fig["held_out_psnr_delta_db"] is not None:
        lines.append(f"small scene, held-out PSNR: {native['backend']} on {native['device']} "
                     f"{native['held_out_psnr']:.2f} dB, {cuda['backend']} on {cuda['device']} "
                     f"{cuda['held_out_psnr']:.2f} dB (difference {fig['held_out_psnr_delta_db']:+.3f} dB)")
    return lines


def _viewer_lines(viewer: dict | None) -> list[str]:
    if not viewer:
        return []
    lines = [f"viewer: {viewer['gaussians']:,} Gaussians at {viewer['width']} x {viewer['height']} on "
             f"{viewer.get('renderer')}"]
    for r in viewer["runs"]:
        ref = r["psnr_vs_reference_db"]
        lines.append(f"  {r['rasterizer']:<8}{'full' if r['budget'] is None else r['budget']:>10} "
                     f"{r['frame_ms']:9.2f} ms {r['fps']:9.1f} fps" + ("" if ref is None else f"  {ref:6.2f} dB "
                                                                       "vs reference"))
    return lines


def summary(report: dict) -> str:
    m, fig = report.get("machine") or {}, report["figures"]
    kind = "dry run: CPU backends, tiny sizes, no GPU figure" if report["dry_run"] else "GPU run"
    lines = [f"CGHair GPU check, {report['started_utc']} ({kind}), commit {report['commit']}",
             f"machine: {m.get('gpu') or 'no CUDA device'}, driver {m.get('driver')}, CUDA {m.get('torch_cuda')} "
             f"(nvcc: {m.get('nvcc')}), torch {m.get('torch')}, gsplat {m.get('gsplat')}, Python {m.get('python')}",
             "stages:"]
    for name, s in report["stages"].items():
        lines.append(f"  {name:<16}{s['status']:<8}{s['seconds']:7.1f} s" + (f"  {s['error']}" if s["error"] else ""))
    kernels, tests = fig["gsplat_kernels"], fig["cuda_tests"]
    if kernels:
        cache = ("its kernels found in " if kernels["cache_found"] else "its kernels compiled into ") \
            + kernels["extensions_dir"] if kernels["backend"] == "gsplat" else "no kernels to compile"
        lines.append(f"{kernels['backend']} first use: {kernels['seconds']:.1f} s ({cache})")
    if tests:
        lines.append(f"CUDA tests: {tests['passed']} passed, {tests['failures']} failed, {tests['errors']} errors, "
                     f"{tests['skipped']} skipped")
        lines += [f"  {t['outcome']}: {t['test']}: {t['message']}" for t in tests["not_passed"]
                  if t["outcome"] != "skipped" or not report["dry_run"]]
    lines += _training_lines(fig) + _viewer_lines(fig["viewer"])
    for name, t in report["targets"].items():
        met = {True: "met", False: "NOT met"}.get(t["met"], "unmeasured" if t["measured"] is None else "not judged "
                                                  "(a dry run's CPU figure)")
        lines.append(f"target {name}: {met} (measured {t['measured']}, target {t['target']})")
    return "\n".join(lines) + "\n"


def _commit() -> str | None:
    try:
        sha = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], cwd=REPO, capture_output=True, text=True,
                             timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        return None
    return (sha + (" (dirty)" if dirty else "")) if sha else None


def _folders(out: Path) -> tuple[Path, Path, Path]:
    """``raw`` and ``logs`` emptied (no figure of an earlier run survives), ``work`` kept (caches)."""
    import shutil

    try:
        out.mkdir(parents=True, exist_ok=True)
        for sub in ("raw", "logs"):
            shutil.rmtree(out / sub, ignore_errors=True)
            (out / sub).mkdir()
        (out / "work").mkdir(exist_ok=True)
        (out / "gpu_check.json").touch()
    except OSError as exc:
        raise CheckError(f"cannot write to {out} ({exc.strerror}); give another folder with --out") from None
    return out / "raw", out / "logs", out / "work"


def _environment(raw: Path, dry: bool) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    env["PYTHONUNBUFFERED"] = "1"
    env.setdefault("TORCH_EXTENSIONS_DIR", str(cache_root() / "torch_extensions"))  # gsplat's compiled kernels
    env.setdefault("MAX_JOBS", str(os.cpu_count() or 1))  # ninja's parallel nvcc jobs
    if dry:
        env["CGH_BENCH_DIR"] = str(raw.parent / "work" / "bench")
    return env


SUBCOMMANDS = ("probe", "first-use", "strands", "install")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in SUBCOMMANDS:
        return _subcommand(argv)
    p = argparse.ArgumentParser(prog="tools/gpu_check.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=os.environ.get("GPU_CHECK_OUT") or "gpu_check_out",
                   help="folder for gpu_check.json, summary.txt and logs/ (default: $GPU_CHECK_OUT or gpu_check_out)")
    p.add_argument("--dry-run", action="store_true", help="the same stages on the CPU, tiny, installing nothing")
    p.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S,
                   help=f"wall-clock seconds for the whole check (default {DEFAULT_BUDGET_S}); a stage gets at most "
                        "what is left")
    p.add_argument("--hair", default=str(REPO.parent / "shared" / "data" / "hair"),
                   help=f"folder with {PAPER_MODEL} for the paper scale (default ../shared/data/hair; without it, "
                        "procedural strands of its size)")
    p.add_argument("--venv", default=str(REPO / ".venv-gpu"), help="the environment to install (default .venv-gpu)")
    p.add_argument("--wheels", default=None, help="install offline from the wheels in this folder")
    p.add_argument("--python", default=None, help="run with this interpreter as it is, installing nothing")
    args = p.parse_args(argv)
    if args.budget <= 0:
        p.error(f"--budget must be > 0 seconds, got {args.budget}")
    if args.python and not Path(args.python).is_file():
        p.error(f"--python {args.python}: no such interpreter")
    try:
        raw, logs, work = _folders(Path(args.out))
    except CheckError as exc:
        print(f"gpu_check: error: {exc}", file=sys.stderr)
        return 2
    return run(args, Path(args.out), raw, logs, work)


def run(args: argparse.Namespace, out: Path, raw: Path, logs: Path, work: Path) -> int:
    """Every stage in turn, the JSON rewritten after each (a check stopped from outside keeps its figures)."""
    py = args.python or (sys.executable if args.dry_run else str(Path(args.venv) / "bin" / "python"))
    start, started = time.monotonic(), datetime.now(timezone.utc)
    report = {"schema": "cghair-gpu-check/1", "dry_run": args.dry_run,
              "started_utc": started.strftime("%Y-%m-%d %H:%M UTC"), "commit": _commit(), "budget_s": args.budget,
              "machine": None, "stages": {}}
    env = _environment(raw, args.dry_run)
    for stage in plan(args, py, raw, work):
        print(f"gpu-check: {stage.name} (limit {stage.timeout_s:.0f} s) ...", flush=True)
        report["stages"][stage.name] = rec = run_stage(stage, env, logs / f"{stage.name}.log", start + args.budget)
        print(f"gpu-check: {stage.name}: {rec['status']} in {rec['seconds']:.1f} s"
              + (f": {rec['error']}" if rec["error"] else ""), flush=True)
        report["machine"] = _read_json(raw / "environment.json")
        report["figures"] = figures(raw)
        report["targets"] = targets(report["figures"], args.dry_run)
        report["wall_seconds"] = round(time.monotonic() - start, 1)
        (out / "gpu_check.json").write_text(json.dumps(report, indent=2) + "\n")
    text = summary(report)
    (out / "summary.txt").write_text(text)
    print(text, end="")
    return 0 if all(s["status"] == "ok" for s in report["stages"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
