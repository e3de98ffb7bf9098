"""The .cgh fuzz target (tests/fuzz/fuzz_decode.py) for a short budget: `make fuzz` runs it for 10 minutes."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("atheris", reason="atheris (the dev extra) runs the fuzz target")

FUZZ_SECONDS = 25


@pytest.mark.slow
def test_fuzz_decode_short_run(tmp_path):
    target = Path(__file__).with_name("fuzz_decode.py")
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]))
    run = subprocess.run([sys.executable, str(target), str(tmp_path), f"-max_total_time={FUZZ_SECONDS}",
                          f"-artifact_prefix={tmp_path}/"], capture_output=True, text=True, env=env,
                         timeout=FUZZ_SECONDS + 120)
    tail = run.stderr[-3000:]
    assert run.returncode == 0, tail
    assert "Done " in tail  # libFuzzer's summary: the budget ran out with no failing input
    runs = int(tail.rsplit("Done ", 1)[1].split()[0])
    assert runs > 1000, tail
