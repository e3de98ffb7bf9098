"""``cgh batch``: a library of strand files through the pipeline (import, cards, encode, round-trip check,
baseline, exports, training) on Dask distributed, with a per-file report that resumes on a rerun.

    from batch import FileOptions, Limits, read_manifest, run_batch
    jobs = read_manifest("grooms/", FileOptions(profiles=("compact", "high")), glob="**/*.hair")
    rows, summary = run_batch(jobs, "out", workers=2)     # or scheduler="tcp://host:8786"

The modules: :mod:`.options` (one file's options), :mod:`.manifest` (the files), :mod:`.pipeline` (one
file's work), :mod:`.sandbox` (its process and limits), :mod:`.records` (resume), :mod:`.engine` (Dask),
:mod:`.report` and :mod:`.plot` (the report), :mod:`.baseline_coder` (the yardstick), :mod:`.cli`.
"""

from __future__ import annotations

import os
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from . import records
from .engine import Limits, connect, run_jobs, wait_for_workers
from .manifest import Job, read_manifest
from .options import FileOptions
from .plot import draw_report
from .report import format_summary, read_report, summarize, write_report

__all__ = ["FileOptions", "Job", "Limits", "draw_report", "format_summary", "read_manifest", "read_report",
           "run_batch", "summarize", "write_report"]


def run_batch(jobs: list[Job], out_dir: str | os.PathLike, *, scheduler: str | None = None, workers: int = 2,
              limits: Limits | None = None, progress: bool = True) -> tuple[list[dict], dict]:
    """Run ``jobs`` (files an earlier run finished with the same input and options are skipped) and write
    the report (``report.json``, ``report.csv``, ``summary.json``, ``report.png``) to ``out_dir``."""
    out_dir = Path(out_dir).resolve()  # the workers' own working folders may differ from this one
    out_dir.mkdir(parents=True, exist_ok=True)
    rows, todo = [], []
    for job in jobs:
        row = records.finished(out_dir, job)
        rows.append(row) if row is not None else todo.append(job)
    run = {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "load_start": _load(),
           "workers": 0, "scheduler": scheduler or "local"}
    start = time.perf_counter()
    try:
        if todo:
            with connect(scheduler, workers) as client:
                run["workers"] = wait_for_workers(client)
                bar = _bar(len(jobs), len(rows)) if progress else None
                try:
                    rows += run_jobs(client, todo, out_dir, limits or Limits(), bar)
                finally:
                    if bar is not None:
                        bar.close()
    finally:  # an interrupted run still reports what it finished
        run.update(wall_s=round(time.perf_counter() - start, 2), load_end=_load())
        summary = summarize(rows, run)
        write_report(out_dir, rows, summary)
        draw_report(rows, out_dir / "report.png")
    return rows, summary


def _bar(total: int, done: int):
    from tqdm import tqdm

    return tqdm(total=total, initial=done, unit="file", desc="cgh batch", file=sys.stderr, dynamic_ncols=True)


def _load() -> str:
    return ", ".join(f"{x:.1f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "n/a"
