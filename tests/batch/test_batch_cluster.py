"""cgh batch on a real Dask cluster: a scheduler and two worker processes on the loopback address, a small
library with a corrupt file, a worker killed mid-file, the report, and the resume on a local cluster."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import cghair_format as cgh
from cghair_format.exchange import save_strands
from cghair_format.synth import synthesize

pytest.importorskip("distributed", reason="cgh batch needs dask[distributed]: pip install -e '.[batch]'")
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
# the library: (path below it, style, strands, points); "big.npz" is the one whose worker is killed
FILES = [("a/wavy.npz", "wavy", 40, 8), ("a/b/curly.hair", "curly", 60, 10), ("straight.data", "straight", 30, 6),
         ("short.npz", "short", 50, 8), ("big.npz", "wavy", 800, 16)]
CORRUPT = "broken.hair"


def _env() -> dict:
    # the scheduler fails a file whose worker dies at once, and gives each worker one file at a time, as the
    # local cluster does (batch.engine.LOCAL_CONFIG)
    return dict(os.environ, PYTHONPATH=str(ROOT), DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES="0",
                DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION="1.0")


@pytest.fixture(scope="module")
def library(tmp_path_factory) -> Path:
    lib = tmp_path_factory.mktemp("library")
    for i, (rel, style, strands, points) in enumerate(FILES):
        (lib / rel).parent.mkdir(parents=True, exist_ok=True)
        save_strands(synthesize(style, strands, points, seed=i), lib / rel)
    (lib / CORRUPT).write_bytes(b"HAIR" + b"\xff" * 124)  # declares 2^32 - 1 strands in 128 bytes
    return lib


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two nanny-less workers, each its own process on 127.0.0.1: (address, worker pids)."""
    folder = tmp_path_factory.mktemp("dask")
    info = folder / "scheduler.json"
    py = [sys.executable, "-m"]
    procs = [subprocess.Popen(py + ["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                                    "--no-dashboard", "--scheduler-file", str(info)], env=_env(), cwd=folder,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(info.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen(py + ["distributed.cli.dask_worker", address, "--host", "127.0.0.1",
                                                "--nthreads", "1", "--no-nanny", "--no-dashboard"], env=_env(),
                                          cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address, [p.pid for p in procs[1:]]
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:  # a worker still closing its last task
                p.kill()
                p.wait()


def _cgh(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cghair_format", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=300, **kw)


def _kill_worker_running_first_task(address: str, pids: list[int], done: threading.Event) -> list[str]:
    """Wait for the batch's first task (the largest file) to run, then SIGKILL its worker mid-file."""
    from distributed import Client

    killed = []
    with Client(address, timeout="20s") as client:
        deadline = time.monotonic() + 120
        while not done.is_set() and time.monotonic() < deadline:
            running = {w: keys for w, keys in client.processing().items() if any(
                str(k).startswith("cgh-batch-0-") for k in keys)}
            if running:
                worker = next(iter(running))
                pid = client.run(os.getpid, workers=[worker])[worker]
                assert pid in pids
                time.sleep(0.3)  # into the task: its worker warming up (seconds) or the file under way
                os.kill(pid, signal.SIGKILL)
                killed.append(worker)
                break
            time.sleep(0.05)
    return killed


def test_library_on_a_cluster_with_a_killed_worker_then_resume(library, cluster, tmp_path):
    address, pids = cluster
    out = tmp_path / "out"
    done = threading.Event()
    killed: list[str] = []
    killer = threading.Thread(target=lambda: killed.extend(_kill_worker_running_first_task(address, pids, done)))
    killer.start()
    run = _cgh("batch", str(library), "-o", str(out), "--scheduler", address, "--profiles", "compact,high",
               "--export", ".ply", "--no-progress")
    done.set()
    killer.join()
    assert killed, "the largest file's task never ran"
    assert run.returncode == 1, run.stderr  # some files failed: exit 1, the report says which
    rows = {r["input"]: r for r in json.loads((out / "report.json").read_text())}
    assert set(rows) == {rel for rel, *_ in FILES} | {CORRUPT}
    assert rows["big.npz"]["status"] == "failed" and "worker running it died" in rows["big.npz"]["error"]
    assert rows[CORRUPT]["status"] == "failed" and "cannot hold" in rows[CORRUPT]["error"]
    for rel, _, strands, points in FILES[:-1]:
        row = rows[rel]
        assert row["status"] == "ok" and row["run"] == "this", row
        assert (row["strands"], row["points"]) == (strands, strands * points)
        stem = out / Path(rel).parent / Path(rel).stem
        for profile, bound in (("compact", 2e-4), ("high", 2e-5)):
            data = Path(f"{stem}.{profile}.cgh").read_bytes()
            assert row[f"bytes_{profile}"] == len(data)
            assert row[f"bits_per_point_{profile}"] == pytest.approx(8 * len(data) / row["points"], abs=1e-3)
            assert 0 < row[f"max_error_{profile}"] <= bound * (1 + 1e-6)
            assert row[f"baseline_bytes_{profile}"] > 0 and row[f"encode_s_{profile}"] > 0
            assert cgh.decode(data).n_strands == strands
        assert Path(f"{stem}.ply").read_bytes().startswith(b"ply")
    csv_lines = (out / "report.csv").read_text().splitlines()
    assert len(csv_lines) == 1 + len(rows) and csv_lines[0].startswith("input,status,run,error")
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["ok"], summary["failed"], summary["workers"]) == (4, 2, 2)
    assert summary["percentiles"]["bytes_compact"]["p50"] > 0
    assert (out / "report.png").read_bytes().startswith(b"\x89PNG")
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]  # nothing half-written
    assert not (out / ".batch" / "big.npz.json").exists()  # the killed file is not recorded as done

    # the skipped files' outputs (the killed file may have written whole outputs before its worker died)
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*.cgh") if not p.name.startswith("big.")}
    rerun = _cgh("batch", str(library), "-o", str(out), "--workers", "2", "--profiles", "compact,high",
                 "--export", ".ply", "--no-progress")  # on a local cluster this time
    assert rerun.returncode == 1, rerun.stderr
    rows = {r["input"]: r for r in json.loads((out / "report.json").read_text())}
    assert [rel for rel, r in rows.items() if r["run"] == "earlier"] == sorted(rel for rel, *_ in FILES[:-1])
    assert rows["big.npz"]["status"] == "ok" and rows["big.npz"]["run"] == "this"
    assert rows[CORRUPT]["status"] == "failed"
    assert all(p.stat().st_mtime_ns == t for p, t in before.items())  # skipped files left as they were
    assert "6 files: 5 ok (4 done earlier), 1 failed" in rerun.stdout

    report = _cgh("batch", "--report", str(out))
    assert report.returncode == 0, report.stderr
    assert "p50" in report.stdout and "bytes_high" in report.stdout


def test_a_file_over_its_limits_or_missing_fails_alone(library, cluster, tmp_path):
    address, _ = cluster
    manifest = tmp_path / "list.json"
    manifest.write_text(json.dumps([{"input": str(library / "big.npz")}, {"input": str(library / "short.npz")},
                                    {"input": str(library / "gone.npz")}]))
    run = _cgh("batch", str(manifest), "-o", str(tmp_path / "out"), "--scheduler", address,
               "--time-per-task", "0.5", "--no-progress")
    rows = {r["input"]: r for r in json.loads((tmp_path / "out" / "report.json").read_text())}
    assert rows["big.npz"]["error"] == "over its time limit of 0.5 s (--time-per-task)", run.stderr
    assert not (tmp_path / "out" / "big.compact.cgh").exists()
    assert rows["gone.npz"]["error"].startswith("FileNotFoundError: [Errno 2] No such file or directory")
