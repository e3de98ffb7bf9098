"""Alembic (``.abc``) grooms and Blender (``.blend``) scenes, written and read through Blender.

No Alembic library installs from PyPI, so Blender (bpy 5.0, in its own interpreter: see
:mod:`.blender`) does the Alembic work in a subprocess, by way of our USD stage
(:mod:`.usd_export`): writing imports the stage and exports Alembic; reading imports the Alembic
file and exports a y-up USD stage that :mod:`.usd_curves` reads.

What Blender 5.0's Alembic writer keeps: curve points, per-point ``width`` (the diameter), the
card mesh with its UVs and normals. What it drops: colours and every other curve attribute
(``groom_*``), so Unreal's groom importer sees the strands with widths but no ``groom_color``.
Alembic states no units: Blender writes metres times the export scale (Unreal and Houdini grooms
are in centimetres: ``--scale 100``). Reading gives strands in Alembic's y-up frame, as stored.
A ``.blend`` is in metres (Blender's unit), so it takes no scale.
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

from ..errors import CghError
from ..strands import Strands
from ._common import StrandFileError, finish

WORKER = Path(__file__).with_name("_bpy_worker") / "groom.py"
TIMEOUT_S = 600
DROPS = ("Blender's Alembic writer keeps curve points and widths (and the card mesh with UVs); "
         "it drops colours and the groom_* attributes")


class BlenderRunError(CghError, RuntimeError):
    """Blender failed on a conversion; the message carries the end of its output."""


def run_worker(op: str, src: Path, dst: Path, scale: float = 1.0) -> None:
    """Run the Blender worker's ``op`` from ``src`` to ``dst`` (see ``_bpy_worker/groom.py``)."""
    from .blender import find_blender_python

    python = find_blender_python()
    try:
        proc = subprocess.run([python, str(WORKER), op, str(src), str(dst), repr(float(scale))],
                              capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired as exc:
        raise BlenderRunError(f"Blender did not finish {op} within {TIMEOUT_S} s") from exc
    if proc.returncode != 0 or "CGH_DONE" not in proc.stdout or not dst.exists():
        tail = [ln for ln in (proc.stdout + proc.stderr).strip().splitlines() if ln.strip()][-3:]
        raise BlenderRunError(f"Blender failed ({op}, exit {proc.returncode}): {' | '.join(tail)}")


def load(path: str | Path) -> Strands:
    """Strands of every curves object in an Alembic file (through Blender), y-up, 1 m per unit."""
    from .usd_curves import load as load_usd

    path = Path(path)
    with tempfile.TemporaryDirectory(prefix="cgh_abc_") as tmp:
        usd = Path(tmp) / "groom.usdc"
        try:
            run_worker("abc_to_usd", path.resolve(), usd)
        except BlenderRunError as exc:
            raise StrandFileError(path, str(exc)) from exc
        strands = load_usd(usd)
    return finish(path, strands)


def save(strands: Strands, path: str | Path) -> None:
    export_blender(Path(path), strands=strands)


def export_blender(path: Path, *, asset=None, strands: Strands | None = None, cards: bool = False,
                   scale: float = 1.0) -> None:
    """Write ``asset`` (curves, and ``cards``) or ``strands`` as Alembic (``.abc``) or as a Blender
    scene (``.blend``: curves with the Principled Hair BSDF, cards with their texture)."""
    from ._common import check_scale, warn
    from .usd_export import export_usd

    ext = path.suffix.lower()
    if ext not in (".abc", ".blend"):
        raise CghError(f"{path}: Blender export writes .abc or .blend, not {ext or 'no extension'}")
    if check_scale(scale) != 1.0 and ext == ".blend":
        raise CghError(f"{path}: a .blend is in metres (Blender's unit); --scale applies to .abc, USD and the rest")
    with tempfile.TemporaryDirectory(prefix="cgh_abc_") as tmp:
        usd = Path(tmp) / "groom.usdc"
        if asset is not None:
            export_usd(usd, asset=asset, cards=cards)
        else:
            export_usd(usd, strands=strands)
        run_worker("usd_to_abc" if ext == ".abc" else "usd_to_blend", usd, path.resolve(), scale)
    if ext == ".abc":
        warn(f"{path}: {DROPS}")
