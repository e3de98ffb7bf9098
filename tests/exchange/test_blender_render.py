"""Blender renders our exports with Cycles as `cgh render` shows the asset: real cards, real client.

Cards built from a real model (Bangs_100.hair) are exported to a .blend (curves with the
Principled Hair BSDF, cards with their texture) and to USD; Blender (bpy 5.0, in a subprocess)
imports them and renders at 48 x 48. The cards must not render black, and the colour Cycles
sees on the curves and cards (linear) must be within 5 % of `cgh render`'s mean hair colour.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

import cghair_format
from cghair_format.cli import main
from cghair_format.exchange._common import srgb_to_linear

SCRIPT = Path(__file__).with_name("blender_scripts") / "render_colours.py"
RES = 64
COLOUR_TOLERANCE = 0.05  # |mean colour difference| / |cgh render's mean colour|, linear RGB


@pytest.fixture(scope="module")
def bangs_cgh(tmp_path_factory):
    from hairdata import hair_path

    from cghair_format.cards import build_cards
    from cghair_format.exchange import load_strands

    build = build_cards(load_strands(hair_path("Bangs_100.hair")), n_cards=40, n_groups=8, points=24,
                        progress=False)
    path = tmp_path_factory.mktemp("bangs") / "bangs.cgh"
    cghair_format.write(build.asset, path)
    return path


def _blender(scene: Path, out: Path) -> dict:
    from test_blender_import import blender_python

    proc = subprocess.run([blender_python(), str(SCRIPT), str(scene), str(out), str(RES)], capture_output=True,
                          text=True, timeout=600)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("CGH_REPORT ")]
    assert proc.returncode == 0 and lines, f"Blender failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    return json.loads(lines[-1][len("CGH_REPORT "):])


def _cgh_render_mean(cgh: Path, tmp: Path) -> np.ndarray:
    """Mean linear hair colour of `cgh render`, weighted by coverage: each pixel's coverage from a
    black and a white background, its colour (the 3DGS blend of display values, divided by the
    coverage) decoded to linear. SH band 0 only: the exports carry the view-independent colour."""
    from PIL import Image

    images = []
    for name, bg in (("k", "0"), ("w", "1")):
        png = tmp / f"ref_{name}.png"
        assert main(["render", str(cgh), "-o", str(png), "--width", "96", "--height", "96",
                     "--background", bg, bg, bg, "--sh-degree", "0"]) == 0
        images.append(np.asarray(Image.open(png).convert("RGB"), np.float64) / 255)
    black, white = images
    coverage = np.clip(1 - (white - black).mean(2), 0, 1).reshape(-1)
    hair = coverage > 0.02  # pixels the hair covers; below, 8-bit rounding swamps the colour
    colour = srgb_to_linear(black.reshape(-1, 3)[hair] / coverage[hair, None])
    return (coverage[hair, None] * colour).sum(0) / coverage[hair].sum()


@pytest.mark.blender
@pytest.mark.gl
@pytest.mark.slow
def test_cycles_renders_cards_and_curves_in_their_colour(bangs_cgh, tmp_path, capsys):
    blend = tmp_path / "bangs.blend"
    assert main(["export", str(bangs_cgh), "-o", str(blend), "--cards"]) == 0
    report = _blender(blend, tmp_path)
    assert report["materials"]["Strands"] == ["StrandHair"] and report["materials"]["Cards"] == ["CardMaterial"]
    reference = _cgh_render_mean(bangs_cgh, tmp_path)
    for part in ("curves", "cards"):
        lit, colour = report[f"{part}_lit"], report[f"{part}_colour"]
        assert colour["alpha"] > 0.02, f"{part}: nothing rendered"
        got = np.array(colour["mean"])
        diff = np.linalg.norm(got - reference) / np.linalg.norm(reference)
        print(f"{part}: Cycles {got.round(4)} vs cgh render {reference.round(4)}: {100 * diff:.1f} %")
        assert diff < COLOUR_TOLERANCE, f"{part}: {got} vs cgh render {reference} ({100 * diff:.1f} %)"
        # lit by a white world the cards reflect a good part of their colour (with normals against
        # their winding they rendered black: under 1 %)
        assert np.mean(lit["mean"]) > 0.3 * np.mean(colour["mean"]), f"{part} render dark: {lit} vs {colour}"


@pytest.mark.blender
def test_blender_imports_curves_cards_and_points(bangs_cgh, tmp_path):
    usd = tmp_path / "bangs.usdc"
    assert main(["export", str(bangs_cgh), "-o", str(usd), "--all"]) == 0
    from test_blender_import import run_blender

    entry = run_blender([(usd, tmp_path / "x.npz")])[str(usd)]
    assert entry["objects"]["Strands"] == "CURVES" and entry["objects"]["Cards"] == "MESH"
    assert entry["objects"]["GaussianPoints"] == "POINTCLOUD"
    assert entry["meshes"]["Cards"]["uv_layers"] == ["st"]
