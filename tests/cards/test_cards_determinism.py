"""``cgh cards`` writes the same bytes for the same input and options: twice in one process (no state
carried between builds: caches, RNGs, thread pools) and in fresh processes whose BLAS and OpenMP
thread counts differ (k-means, reductions)."""

import os
import subprocess
import sys
from pathlib import Path

from hairdata import hair_path

from cghair_format.cli import main

REPO = Path(__file__).resolve().parents[2]
# Curly_100 has 10 to 47 points a strand: the build resamples them, then clusters, fits and encodes
ARGS = ["--cards", "20", "--groups", "4", "--segments", "8", "--no-progress"]


def _in_fresh_process(strands: Path, out: Path, threads: str | None) -> bytes:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.pop(name, None)
        if threads is not None:
            env[name] = threads
    subprocess.run([sys.executable, "-m", "cghair_format", "cards", str(strands), "-o", str(out), *ARGS],
                   check=True, capture_output=True, env=env, timeout=300)
    return out.read_bytes()


def test_the_same_cards_give_the_same_bytes_in_one_process_and_across_processes(tmp_path, capsys):
    strands = hair_path("Curly_100.ply")
    files = []
    for i in range(2):
        out = tmp_path / f"here{i}.cgh"
        assert main(["cards", str(strands), "-o", str(out), *ARGS]) == 0
        files.append(out.read_bytes())
    capsys.readouterr()
    files.append(_in_fresh_process(strands, tmp_path / "one_thread.cgh", "1"))
    files.append(_in_fresh_process(strands, tmp_path / "default_threads.cgh", None))
    assert len(files[0]) > 1000
    assert all(f == files[0] for f in files[1:]), [len(f) for f in files]
