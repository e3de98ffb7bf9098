"""tools/gpu_check.py (`make gpu-check`): its dry run on the CPU end to end, so the GPU check cannot rot
between the rare runs on a GPU machine, and the stage runner's time limits."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOOL = ROOT / "tools" / "gpu_check.py"


def _module():
    spec = importlib.util.spec_from_file_location("gpu_check", TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


gpu_check = _module()


def _stage(tmp_path, code: str, timeout_s: float, deadline_s: float = 60.0) -> dict:
    stage = gpu_check.Stage("s", [[sys.executable, "-c", code]], timeout_s)
    return gpu_check.run_stage(stage, {}, tmp_path / "s.log", time.monotonic() + deadline_s)


def test_a_stage_past_its_limit_is_killed_with_its_children_and_says_so(tmp_path):
    code = "import subprocess, sys, time; subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)']); " \
           "print('started', flush=True); time.sleep(60)"
    t = time.monotonic()
    rec = _stage(tmp_path, code, 2.0)
    assert time.monotonic() - t < 20
    assert rec["status"] == "timeout" and rec["error"] == "stopped after its limit of 2 s"
    assert "started" in (tmp_path / "s.log").read_text()


def test_a_failed_stage_gives_its_last_line_and_a_stage_past_the_budget_is_skipped(tmp_path):
    code = "import sys; print('noise', flush=True); sys.exit('bench: error: hair model x not found')"
    rec = _stage(tmp_path, code, 30)
    assert rec["status"] == "failed" and rec["error"] == "bench: error: hair model x not found"
    rec = _stage(tmp_path, "print('never')", 30, deadline_s=0.5)
    assert rec["status"] == "skipped" and "no time left" in rec["error"]


def test_an_unwritable_out_folder_is_one_line_and_exit_2(tmp_path):
    (tmp_path / "file").write_text("")
    run = subprocess.run([sys.executable, str(TOOL), "--dry-run", "--out", str(tmp_path / "file" / "out")],
                         capture_output=True, text=True)
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and "give another folder with --out" in run.stderr


def test_make_gpu_check_does_not_depend_on_the_cpu_venv():
    """`make venv` pins the CPU build of torch: the GPU check must never pull it over the machine's CUDA build."""
    rule = next(x for x in (ROOT / "Makefile").read_text().splitlines() if x.startswith("gpu-check:"))
    assert rule.strip() == "gpu-check:"


@pytest.mark.slow
@pytest.mark.gl
def test_dry_run_runs_every_stage_on_the_cpu_and_installs_nothing(tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, str(TOOL), "--dry-run", "--out", str(out), "--venv", str(tmp_path / "venv")],
                         capture_output=True, text=True, cwd=ROOT, timeout=600)
    report = json.loads((out / "gpu_check.json").read_text())
    assert run.returncode == 0, (run.stdout[-3000:], report["stages"])
    assert report["dry_run"] and not (tmp_path / "venv").exists()
    assert list(report["stages"]) == ["environment", "scene", "gsplat_kernels", "cuda_tests", "train_gsplat", "viewer",
                                      "train_native", "train_cuda", "train_reference"]
    fig = report["figures"]
    assert fig["cuda_tests"]["passed"] > 0 and fig["cuda_tests"]["failures"] == fig["cuda_tests"]["errors"] == 0
    assert fig["train_gsplat"]["backend"] == "native" and fig["train_gsplat"]["iterations_per_second"] > 0
    assert fig["train_native"]["backend"] == "native" and fig["train_cuda"]["backend"] == "reference"
    assert abs(fig["held_out_psnr_delta_db"]) <= gpu_check.PSNR_TOLERANCE_DB and fig["speedup_over_reference"] > 0
    runs = {(r["rasterizer"], r["budget"] is None) for r in fig["viewer"]["runs"]}
    assert runs == {("compute", True), ("compute", False), ("raster", True), ("raster", False)}
    assert report["targets"]["gsplat_iterations_per_second"]["met"] is None  # the CPU's speed judges nothing
    assert report["targets"]["held_out_psnr_delta_db"]["met"] and report["targets"]["cuda_tests_not_passed"]["met"]
    text = (out / "summary.txt").read_text()
    assert "dry run" in text and "small scene, held-out PSNR" in text and text in run.stdout
    assert sorted(p.name for p in (out / "logs").iterdir()) == sorted(f"{s}.log" for s in report["stages"])
