"""A real 3DGS client reads our PLY: PlayCanvas splat-transform (npm), converting it to SPZ and SOG.

The CLI lives in .venv/node (``make splat-transform``; this test runs that target when the CLI is
missing, so a fresh machine needs only Node.js and npm; ``CGH_SPLAT_TRANSFORM`` names another).
Hair is exported in metres from Bangs_100.hair, once as metres and once with ``--scale 100``
(centimetres): SPZ stores positions as 24-bit fixed point with 12 fractional bits (steps of
1/4096 unit, range +-2048 units), so metre-scale hair snaps to 0.24 mm while centimetres keep
2.4 um; SOG stores sign(x) log(1 + |x|) in 16 bits per axis over the data's range.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cghair_format.exchange.ply_3dgs import read_3dgs_ply

REPO = Path(__file__).resolve().parents[2]
CLI = REPO / ".venv" / "node" / "node_modules" / ".bin" / "splat-transform"
SPZ_STEP = 1 / 4096  # SPZ v2+ position quantum, in file units
SOG_LEVELS = 65535  # 16-bit positions


@pytest.fixture(scope="module")
def splat_transform() -> str:
    env = os.environ.get("CGH_SPLAT_TRANSFORM")
    if env:
        return env
    if not CLI.exists():
        if shutil.which("npm") is None or shutil.which("make") is None:
            pytest.fail("splat-transform needs Node.js and npm (apt-get install nodejs npm); "
                        "deselect with -m 'not node'")
        proc = subprocess.run(["make", "-C", str(REPO), "splat-transform"], capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0 and CLI.exists(), f"npm install failed:\n{proc.stderr[-2000:]}"
    return str(CLI)


def _run(cli: str, *args) -> str:
    proc = subprocess.run([cli, "-q", "-w", *map(str, args)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"splat-transform {args} failed:\n{proc.stdout[-1500:]}{proc.stderr[-1500:]}"
    return proc.stdout


@pytest.fixture(scope="module")
def bangs_metres(tmp_path_factory):
    """Bangs_100 (centimetres) built into cards, in metres: a .cgh of real hair at real size."""
    from hairdata import hair_path

    import cghair_format
    from cghair_format.cards import build_cards
    from cghair_format.exchange import load_strands
    from cghair_format.exchange._common import scale_strands

    strands = scale_strands(load_strands(hair_path("Bangs_100.hair"), units=0.01), 0.01)  # cm -> m
    assert strands.meters_per_unit == 1.0
    build = build_cards(strands, n_cards=40, n_groups=8, points=24, progress=False)
    path = tmp_path_factory.mktemp("bangs") / "bangs.cgh"
    cghair_format.write(build.asset, path)
    return path


def _nearest_error(ours: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """Per decoded Gaussian, the distance (max over axes) to ours: the same index where the order is
    kept, else the nearest (SOG reorders along a Morton curve)."""
    if np.abs(theirs - ours).max() < 0.01 * np.ptp(ours, 0).max():
        return np.abs(theirs - ours).max(1)
    from scipy.spatial import cKDTree

    _, idx = cKDTree(ours).query(theirs)
    return np.abs(theirs - ours[idx]).max(1)


@pytest.mark.node
@pytest.mark.slow
def test_splat_transform_reads_and_converts_our_ply(splat_transform, bangs_metres, tmp_path, capsys):
    from cghair_format.cli import main

    errors = {}
    for scale in (1, 100):
        ply = tmp_path / f"bangs_{scale}.ply"
        assert main(["export", str(bangs_metres), "-o", str(ply), "--scale", str(scale)]) == 0
        ours = read_3dgs_ply(ply)
        info = json.loads(_run(splat_transform, ply, "--info", "json", "null"))
        assert json.dumps(info).count(str(ours.count)) >= 1, info  # it counts every Gaussian
        for fmt in ("spz", "sog"):
            packed, back = tmp_path / f"b{scale}.{fmt}", tmp_path / f"b{scale}_{fmt}.ply"
            _run(splat_transform, *(["-g", "cpu"] if fmt == "sog" else []), ply, packed)
            _run(splat_transform, packed, back)
            theirs = read_3dgs_ply(back)
            assert theirs.count == ours.count
            err = _nearest_error(ours.means.astype(np.float64), theirs.means.astype(np.float64))
            errors[fmt, scale] = float(err.max()) / scale  # in metres
            if fmt == "spz":
                assert err.max() <= SPZ_STEP / 2 * 1.001 + 1e-7 * np.abs(ours.means).max()
            else:
                f = np.sign(ours.means) * np.log1p(np.abs(ours.means.astype(np.float64)))
                step = np.ptp(f, 0) / SOG_LEVELS
                bound = ((1 + np.abs(ours.means).max(0)) * step * 1.01).max()  # one 16-bit step (it floors)
                assert err.max() <= bound, (fmt, scale, err.max(), bound)
    print("max position error, metres: " + ", ".join(f"{f} at --scale {s}: {e:.3g}" for (f, s), e in errors.items()))
    # centimetres are the suitable unit for SPZ: 100 x finer than metres (SOG's log mapping prefers
    # metres: 60 um there, 108 um in centimetres)
    assert errors["spz", 100] < errors["spz", 1] / 50
    assert errors["spz", 100] < 2e-6  # 1.2 um, far below a hair's 26 um radius
