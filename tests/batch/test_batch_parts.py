"""cgh batch's parts without a cluster: manifests, per-file options, the resume records, the sandbox's
limits, one file's pipeline, the report and its plot, and the command line's refusals."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import cghair_format as cgh
from batch import FileOptions, read_manifest, records, summarize
from batch.engine import distributed
from batch.manifest import Job
from batch.pipeline import run_file
from batch.plot import draw_report
from batch.report import format_summary, read_report, write_report
from batch.sandbox import TaskFault, run_limited
from cghair_format.errors import CghError, MissingDependencyError
from cghair_format.exchange import save_strands
from cghair_format.synth import synthesize

ROOT = Path(__file__).resolve().parents[2]


def _strands(path: Path, strands: int = 40, points: int = 8, seed: int = 0) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    save_strands(synthesize("wavy", strands, points, seed=seed), path)
    return path


def test_a_folder_mirrors_its_tree_and_leaves_out_the_output_folder(tmp_path):
    _strands(tmp_path / "lib" / "x" / "one.npz")
    _strands(tmp_path / "lib" / "two.hair")
    (tmp_path / "lib" / "notes.txt").write_text("not hair")
    _strands(tmp_path / "lib" / "out" / "old.npz")
    jobs = read_manifest(tmp_path / "lib", exclude=tmp_path / "lib" / "out")
    assert [str(j.rel) for j in jobs] == ["two.hair", "x/one.npz"]
    assert jobs[1].output(tmp_path / "o", ".compact.cgh") == tmp_path / "o" / "x" / "one.compact.cgh"
    assert [str(j.rel) for j in read_manifest(tmp_path / "lib", glob="*.hair")] == ["two.hair"]


def test_csv_and_json_manifests_carry_per_file_options(tmp_path):
    _strands(tmp_path / "a.npz")
    _strands(tmp_path / "sub" / "b.npz")
    (tmp_path / "list.csv").write_text("input,profiles,cards,check\na.npz,compact;high,3,no\nsub/b.npz,,,\n")
    a, b = read_manifest(tmp_path / "list.csv", FileOptions(exports=(".ply",)))
    assert a.options == FileOptions(profiles=("compact", "high"), cards=3, check=False, exports=(".ply",))
    assert b.options == FileOptions(exports=(".ply",)) and str(b.rel) == "sub/b.npz"
    (tmp_path / "list.json").write_text(json.dumps([{"input": "a.npz", "points": 16, "exports": [".abc"]}]))
    (job,) = read_manifest(tmp_path / "list.json")
    assert (job.options.points, job.options.exports) == (16, (".abc",))
    assert a.options.key() != b.options.key() and b.options.key() == FileOptions(exports=(".ply",)).key()


@pytest.mark.parametrize("text, message", [
    ("input,colour\na.npz,red\n", "unknown option 'colour'"),
    ("input,cards\na.npz,many\n", "option cards cannot be 'many'"),
    ("input,profiles\na.npz,tiny\n", "unknown profile tiny"),
    ("input,exports\na.npz,.obj\n", "cannot export .obj"),
    ("cards\n3\n", "no input path"),
    ("input\na.npz\nsub/../a.npz\n", "would write the same outputs"),
])
def test_a_bad_manifest_is_refused_saying_where(tmp_path, text, message):
    _strands(tmp_path / "a.npz")
    (tmp_path / "sub").mkdir()
    (tmp_path / "list.csv").write_text(text)
    with pytest.raises(CghError, match=message):
        read_manifest(tmp_path / "list.csv")


def test_bad_manifest_files_are_refused(tmp_path):
    (tmp_path / "list.json").write_text("{not json")
    with pytest.raises(CghError, match="not a JSON manifest"):
        read_manifest(tmp_path / "list.json")
    (tmp_path / "list.json").write_text('{"input": "a.npz"}')
    with pytest.raises(CghError, match="a list of objects"):
        read_manifest(tmp_path / "list.json")
    with pytest.raises(CghError, match="no input files"):
        read_manifest(tmp_path, glob="*.hair")
    with pytest.raises(CghError, match="no such folder or manifest"):
        read_manifest(tmp_path / "missing")


def test_one_files_pipeline_its_row_and_its_record(tmp_path):
    src = _strands(tmp_path / "lib" / "h.npz", strands=45, points=10)
    out = tmp_path / "out"
    job = Job(src, Path("h.npz"), FileOptions(profiles=("compact", "lossless"), exports=(".ply",)))
    row = run_file(job, out)
    assert (row["status"], row["strands"], row["points"], row["cards"]) == ("ok", 45, 450, 1)
    assert row["bytes_compact"] == (out / "h.compact.cgh").stat().st_size
    assert row["cards_error"] < 1e-6  # the builder's float asset holds the input's points (float32 rounding)
    assert 0 < row["max_error_compact"] <= 2e-4 and row["max_error_lossless"] < 1e-6
    assert "baseline_bytes_lossless" not in row and row["ratio_compact"] == pytest.approx(
        row["geometry_bytes_compact"] / row["baseline_bytes_compact"], rel=1e-3)
    assert row["outputs"] == "h.compact.cgh;h.lossless.cgh;h.ply"
    assert records.finished(out, job) == row | {"run": "earlier"}
    os.utime(src, ns=(time.time_ns(), time.time_ns() + 10**9))  # touched, same bytes: still done
    assert records.finished(out, job) is not None
    assert records.finished(out, Job(src, job.rel, FileOptions())) is None  # other options: redo
    (out / "h.ply").unlink()
    assert records.finished(out, job) is None  # an output gone: redo
    _strands(src, strands=45, points=10, seed=7)  # other points, same size
    assert records.finished(out, job) is None


def _nap():
    time.sleep(30)


def _die():
    os.kill(os.getpid(), signal.SIGKILL)  # as a crash in compiled code, or the kernel's out-of-memory killer


def _hog():
    return float(np.ones(400 << 20 >> 3).sum())  # 400 MiB


def test_the_sandbox_keeps_a_files_faults_to_that_file():
    assert run_limited(divmod, (7, 2), memory_mb=64, seconds=30) == (3, 1)
    with pytest.raises(TaskFault, match="over its memory limit of 128 MiB"):
        run_limited(_hog, (), memory_mb=128, seconds=30)
    start = time.monotonic()
    with pytest.raises(TaskFault, match="over its time limit of 0.5 s"):
        run_limited(_nap, (), memory_mb=64, seconds=0.5)
    assert time.monotonic() - start < 10
    with pytest.raises(TaskFault, match="died \\(signal SIGKILL\\)"):
        run_limited(_die, (), memory_mb=64, seconds=30)
    with pytest.raises(TaskFault, match="^ZeroDivisionError: integer division"):
        run_limited(divmod, (1, 0), memory_mb=64, seconds=30)


def _rows() -> list[dict]:
    ok = [{"input": f"f{i}.npz", "status": "ok", "run": "this", "error": "", "strands": 100 * (i + 1),
           "points": 1000 * (i + 1), "bytes_compact": 5000 * (i + 1), "ratio_compact": 0.8 + 0.1 * i,
           "baseline_bytes_compact": 6000 * (i + 1), "import_s": 0.1, "cards_s": 1.0, "encode_s_compact": 2.0,
           "decode_s_compact": 0.5, "total_s": 4.0} for i in range(5)]
    return ok + [{"input": "bad.hair", "status": "failed", "run": "this", "error": "broken"}]


def test_the_summary_report_and_plot(tmp_path):
    summary = summarize(_rows(), {"wall_s": 10.0, "workers": 2, "load_start": "1.0", "load_end": "2.0"})
    assert (summary["files"], summary["ok"], summary["failed"], summary["files_per_minute"]) == (6, 5, 1, 30.0)
    assert summary["percentiles"]["strands"] == {"p0": 100, "p50": 300, "p90": 460, "p99": 496, "p100": 500}
    assert summary["time_split"]["encode"] == {"s": 10.0, "share": 0.5}
    assert summary["time_split"]["other"]["s"] == pytest.approx(2.0)
    write_report(tmp_path, _rows(), summary)
    rows, again = read_report(tmp_path)
    assert [r["input"] for r in rows] == ["bad.hair"] + [f"f{i}.npz" for i in range(5)] and again == summary
    assert "5 ok (0 done earlier), 1 failed" in format_summary(summary)
    from PIL import Image

    with Image.open(draw_report(rows, tmp_path / "plot.png")) as img:
        assert img.size == (1120, 440)
        assert len(img.getcolors(1 << 16)) > 3  # dots, grid and labels drawn


def test_a_missing_engine_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(MissingDependencyError, match=r"pip install 'cghair\[batch\]'"):
        distributed()


@pytest.mark.parametrize("args, message", [
    ([], "give a folder or manifest and -o OUT_DIR"),
    (["--report", "{tmp}"], "no report.json and summary.json here"),
    (["{tmp}", "-o", "{tmp}/o", "--report", "{tmp}"], "give no manifest and no -o with it"),
    (["{tmp}", "-o", "{tmp}/o", "--glob", "*.hair"], "no input files"),
    (["{tmp}/nowhere", "-o", "{tmp}/o"], "no such folder or manifest"),
    (["{tmp}", "-o", "{tmp}/o", "--profiles", "small"], "unknown profile small"),
    (["{tmp}", "-o", "{tmp}/a.npz"], "cannot write"),
])
def test_the_command_line_refuses_in_one_line(tmp_path, args, message):
    _strands(tmp_path / "a.npz")
    run = subprocess.run([sys.executable, "-m", "cghair_format", "batch",
                          *[a.format(tmp=tmp_path) for a in args]], capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    assert run.returncode == 2 and message in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr


@pytest.mark.slow
def test_a_file_with_a_dataset_is_trained(tmp_path):
    pytest.importorskip("torch", reason="training needs torch: pip install -e '.[training]'")
    from training.datasets.synthetic import render_dataset

    src = _strands(tmp_path / "h.npz", strands=40, points=8)
    render_dataset(synthesize("wavy", 40, 8, seed=0), tmp_path / "data", views=4, res=32)
    row = run_file(Job(src, Path("h.npz"), FileOptions(dataset=str(tmp_path / "data"), iters=2)), tmp_path / "out")
    assert row["train_s"] > 0 and row["outputs"] == "h.compact.cgh;h.trained.cgh"
    trained = cgh.read(tmp_path / "out" / "h.trained.cgh")
    assert trained.n_strands == 40 and trained.metadata["training"]["iterations_run"] == 2
