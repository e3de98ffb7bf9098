"""Warnings print as one clean line through the CLI: ``cgh: warning: ...``, no category, no source."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

from cghair_format.cli import format_warning, main
from cghair_format.exchange import save_strands
from cghair_format.strands import Strands

ROOT = Path(__file__).resolve().parents[2]


def _odd_strands(path: Path) -> Path:
    """Strands of 12 points, which the TressFX writer warns about (runtimes expect a power of two)."""
    pts = np.cumsum(np.full((5, 12, 3), 0.01, np.float32), axis=1)
    save_strands(Strands.from_array(pts), path)
    return path


def test_format_warning_is_one_line():
    assert format_warning(UserWarning("two\n  lines")) == "cgh: warning: two lines"


def test_a_verb_prints_its_warning_as_one_line(tmp_path, capsys):
    src = _odd_strands(tmp_path / "s.npz")
    assert main(["convert", str(src), str(tmp_path / "s.tfx")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("cgh: warning: ") and "TressFX" in err[0], err
    assert warnings.showwarning is not None and warnings.showwarning.__name__ != "_show_warning"  # hook undone


def test_the_command_line_process_prints_one_line(tmp_path):
    src = _odd_strands(tmp_path / "s.npz")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "cghair_format", "convert", str(src), str(tmp_path / "s.tfx")],
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("cgh: warning: "), proc.stderr
    assert "UserWarning" not in proc.stderr and "warnings.warn" not in proc.stderr
