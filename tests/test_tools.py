"""The repository's tools: the benchmark-table generator and the baseline strand coder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from bench import baseline_coder

ROOT = Path(__file__).resolve().parents[1]


def test_bench_tables_renders_rows_tables_and_scalars(tmp_path):
    data = {"datetime": "2026-11-25T10:00:00", "machine_info": {"cpu": {"brand_raw": "cpu X", "count": 2}},
            "commit_info": {"id": "abcdef0123456", "dirty": False},
            "benchmarks": [
                {"fullname": "tests/bench/a.py::test_rows", "extra_info": {"rows": [{"model": "m", "bytes": 1234}]}},
                {"fullname": "tests/bench/a.py::test_lines", "extra_info": {"table": ["a  b", "1  2"]}},
                {"fullname": "tests/bench/a.py::test_scalars", "extra_info": {"fps": 7.5}}]}
    src = tmp_path / "b.json"
    src.write_text(json.dumps(data))
    out = tmp_path / "b.md"
    subprocess.run([sys.executable, str(ROOT / "tools" / "bench_tables.py"), str(src), "-o", str(out)], check=True)
    text = out.read_text()
    assert "cpu X, 2 cores" in text and "abcdef0123" in text
    assert "| model | bytes |" in text and "| m | 1,234 |" in text
    assert "```\na  b\n1  2\n```" in text
    assert "| fps | 7.5 |" in text


def test_bench_tables_refuses_a_missing_file_in_one_line(tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "tools" / "bench_tables.py"), str(tmp_path / "none.json")],
                         capture_output=True, text=True)
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and "cannot read" in run.stderr


def test_baseline_coder_keeps_the_bound_on_strands_of_unequal_lengths():
    rng = np.random.default_rng(0)
    offsets = np.array([0, 5, 12, 40, 41])
    points = np.cumsum(rng.normal(0, 0.3, (41, 3)), 0).astype(np.float32)
    size, decoded = baseline_coder.encode(points, offsets, 1e-3)
    assert np.linalg.norm(decoded - points, axis=1).max() <= 1e-3 * (1 + 1e-6)
    assert 0 < size < points.nbytes


def test_baseline_deltas_invert():
    rng = np.random.default_rng(1)
    offsets = np.array([0, 3, 9])
    q = rng.integers(-50, 50, (9, 3))
    for order in (1, 2):
        d = baseline_coder._deltas(q, offsets, order)
        within = np.arange(9) - np.repeat(offsets[:-1], np.diff(offsets))
        for k in range(order, 0, -1):  # undo pass k: a running sum from each strand's k-th value on
            for i in np.nonzero(within >= k)[0]:
                d[i] += d[i - 1]
        assert (d == q).all()
