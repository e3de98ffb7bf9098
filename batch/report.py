"""The batch's report: one row per file (``report.json``, ``report.csv``) and a summary (``summary.json``).

A row's columns: ``input`` (below the inputs' folder), ``status`` (ok, failed), ``run`` (this, or earlier:
skipped on a rerun), ``error``; ``strands``, ``points`` (all strands'), ``min_points``, ``max_points``,
``bbox_diagonal``, ``cards``, ``groups``, ``cards_error`` (the card builder's largest point error before
quantization, over the diagonal); per profile P: ``bytes_P`` (the file), ``bits_per_point_P``,
``geometry_bytes_P`` (the chunks holding the points), ``baseline_bytes_P`` (the quantize + delta + zstd
coder at P's bound on the same points, :mod:`.baseline_coder`), ``ratio_P`` (geometry over baseline),
``max_error_P`` (largest distance of a decoded point from the input's own, over the bounding-box
diagonal), ``encode_s_P``, ``decode_s_P``, ``baseline_s_P``; ``import_s``, ``cards_s``, ``export_EXT_s``, ``train_s``,
``total_s``, ``cpu_s`` (the file's process's CPU time), ``peak_rss_mb`` (its peak resident memory),
``outputs``.
"""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import numpy as np

from cghair_format.atomic import write_text
from cghair_format.errors import CghError

PERCENTILES = (0, 50, 90, 99, 100)
# the columns the summary gives percentiles of (P: each profile's)
SUMMARIZED = ("strands", "points", "cards_error", "bytes_P", "bits_per_point_P", "ratio_P", "max_error_P",
              "encode_s_P", "decode_s_P", "import_s", "cards_s", "total_s", "cpu_s",
              "peak_rss_mb")
# the time split: stage -> the columns of its seconds (P: any profile, EXT: any export)
STAGES = {"import": "import_s", "cards": "cards_s", "encode": "encode_s_P", "decode": "decode_s_P",
          "baseline": "baseline_s_P", "export": "export_EXT_s", "train": "train_s"}


def profiles_of(rows: list[dict]) -> list[str]:
    """The profiles the rows were encoded with, in the order first met."""
    seen: dict[str, None] = {}
    for row in rows:
        for key in row:
            if key.startswith("bytes_"):
                seen.setdefault(key[len("bytes_"):])
    return list(seen)


def columns_of(rows: list[dict]) -> list[str]:
    seen: dict[str, None] = {}
    for row in rows:
        for key in row:
            seen.setdefault(key)
    return list(seen)


def summarize(rows: list[dict], run: dict) -> dict:
    """Counts, the percentiles of :data:`SUMMARIZED` over the files done, and this run's time split."""
    ok = [r for r in rows if r["status"] == "ok"]
    this = [r for r in ok if r["run"] == "this"]
    summary = dict(run, files=len(rows), ok=len(ok), failed=len(rows) - len(ok), done_this_run=len(this),
                   skipped=len(ok) - len(this), percentiles={})
    for pattern in SUMMARIZED:
        for key in ([pattern.replace("_P", f"_{p}") for p in profiles_of(rows)] if "_P" in pattern else [pattern]):
            values = np.array([r[key] for r in ok if isinstance(r.get(key), (int, float))], np.float64)
            if len(values):
                summary["percentiles"][key] = {f"p{q}": float(f"{np.percentile(values, q):.6g}") for q in PERCENTILES}
    total = sum(r["total_s"] for r in this)
    patterns = {stage: re.compile(p.replace("P", "[^_]+").replace("EXT", "[^_]+")) for stage, p in STAGES.items()}
    split = {stage: sum(v for r in this for k, v in r.items() if pattern.fullmatch(k))
             for stage, pattern in patterns.items()}
    split["other"] = total - sum(split.values())  # the error measure, writing files
    summary["time_split"] = {k: {"s": round(v, 2), "share": round(v / total, 4) if total else 0.0}
                             for k, v in split.items()}
    if run.get("wall_s") and this:
        summary["files_per_minute"] = round(60 * len(this) / run["wall_s"], 2)
    return summary


def write_report(out_dir: Path, rows: list[dict], summary: dict) -> list[Path]:
    """``report.json``, ``report.csv`` and ``summary.json`` in ``out_dir``, each written atomically."""
    rows = sorted(rows, key=lambda r: r["input"])
    columns = columns_of(rows)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    paths = [out_dir / "report.json", out_dir / "report.csv", out_dir / "summary.json"]
    write_text(paths[0], json.dumps(rows, indent=1) + "\n")
    write_text(paths[1], text.getvalue())
    write_text(paths[2], json.dumps(summary, indent=1) + "\n")
    return paths


def read_report(out_dir: Path) -> tuple[list[dict], dict]:
    """The rows and summary a run wrote to ``out_dir``."""
    try:
        rows = json.loads((out_dir / "report.json").read_text(encoding="utf-8"))
        summary = json.loads((out_dir / "summary.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CghError(f"{out_dir}: no report.json and summary.json here; run cgh batch MANIFEST -o {out_dir} "
                       "first") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise CghError(f"{out_dir}: the report is not readable JSON ({exc}); run cgh batch again") from None
    if not isinstance(rows, list) or not all(isinstance(r, dict) and "input" in r and "status" in r for r in rows):
        raise CghError(f"{out_dir}/report.json is not a cgh batch report")
    return rows, summary


def format_summary(summary: dict) -> str:
    """The summary as a few lines of text: counts, throughput, the time split and the percentiles."""
    lines = [f"{summary['files']:,} files: {summary['ok']:,} ok ({summary['skipped']:,} done earlier), "
             f"{summary['failed']:,} failed"]
    if "files_per_minute" in summary:
        workers = f"{summary['workers']} worker{'s' if summary['workers'] != 1 else ''}"
        lines.append(f"{summary['done_this_run']:,} done in {summary['wall_s']:.1f} s on {workers}: "
                     f"{summary['files_per_minute']:.1f} files a minute (load average "
                     f"{summary['load_start']} at the start, {summary['load_end']} at the end)")
    split = summary.get("time_split", {})
    if any(v["s"] > 0 for v in split.values()):
        lines.append("time: " + ", ".join(f"{k} {v['share']:.0%}" for k, v in split.items() if v["s"] > 0))
    heads = [f"p{q}" for q in PERCENTILES]
    lines.append(f"{'':<26}" + "".join(f"{h:>12}" for h in heads))
    for key, values in summary["percentiles"].items():
        lines.append(f"{key:<26}" + "".join(f"{values[h]:>12.4g}" for h in heads))
    return "\n".join(lines)
