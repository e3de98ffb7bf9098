"""The Cycles engine: a clear error without bpy; a tiny render with it (marked blender)."""

from __future__ import annotations

import numpy as np
import pytest

from cghair_format.errors import MissingDependencyError
from training.datasets.cycles import bpy_available
from training.datasets.read import read_dataset
from training.datasets.synthetic import render_dataset


def test_without_bpy_the_error_names_the_extra(tmp_path, strands, monkeypatch):
    import importlib.util

    # point the Blender finder at nothing, and hide any bpy of the running interpreter
    monkeypatch.setenv("CGH_BLENDER_PYTHON", str(tmp_path / "no-such-python"))
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "bpy" else real(name, *a))
    assert not bpy_available()
    with pytest.raises(MissingDependencyError, match=r"cghair\[blender\]"):
        render_dataset(strands, tmp_path, views=2, res=8, engine="cycles")


@pytest.mark.blender
@pytest.mark.slow
def test_cycles_renders_a_tiny_dataset(tmp_path, strands):
    if not bpy_available():
        pytest.skip("bpy (Blender as a Python module, the 'blender' extra) is not installed")
    render_dataset(strands, tmp_path, views=3, res=24, engine="cycles", samples=4)
    ds = read_dataset(tmp_path)
    for v in ds.train + ds.test:
        a = v.image[..., 3]
        assert 0.03 < a.mean() < 0.9  # hair in frame on a transparent background
        assert a[0].max() < 0.5  # nothing at the top border
        lit = v.image[..., :3][a > 0.5]
        assert lit.mean() > 0.02  # the light rig lights it
    # the same framing as the splat engine: masks overlap well
    splat = render_dataset(strands, tmp_path / "splat", views=3, res=24, engine="splat")
    overlap = np.minimum(ds.train[0].image[..., 3], splat.train[0].image[..., 3]).sum()
    assert overlap > 0.3 * splat.train[0].image[..., 3].sum()


def _needs_bpy():
    if not bpy_available():
        pytest.skip("bpy (Blender as a Python module, the 'blender' extra) is not installed")


@pytest.mark.blender
@pytest.mark.slow
def test_cycles_renders_the_strands_colours(tmp_path, strands):
    from dataclasses import replace

    _needs_bpy()
    means = {}
    for name, rgb in (("red", (0.8, 0.1, 0.1)), ("blue", (0.1, 0.1, 0.8))):
        coloured = replace(strands, colors=np.tile(np.float32(rgb), (len(strands.points), 1)))
        view = render_dataset(coloured, tmp_path / name, views=2, res=32, engine="cycles", samples=4).train[0]
        means[name] = view.image[..., :3][view.image[..., 3] > 0.5].mean(0)
    assert means["red"][0] > means["red"][2] + 0.1 and means["blue"][2] > means["blue"][0] + 0.1, means


def _roughness(view) -> float:
    """Mean absolute Laplacian of the luminance on the hair: sampling noise raises it."""
    lum = view.image[..., :3].mean(-1)
    lap = 4 * lum[1:-1, 1:-1] - lum[:-2, 1:-1] - lum[2:, 1:-1] - lum[1:-1, :-2] - lum[1:-1, 2:]
    return float(np.abs(lap)[view.image[1:-1, 1:-1, 3] > 0.9].mean())


@pytest.mark.blender
@pytest.mark.slow
def test_cycles_multitone_with_the_denoiser(tmp_path, strands):
    _needs_bpy()
    noisy = render_dataset(strands, tmp_path / "n", views=2, res=32, engine="cycles", samples=2, multitone=3)
    clean = render_dataset(strands, tmp_path / "d", views=2, res=32, engine="cycles", samples=2, multitone=3,
                           denoise=True)
    assert clean.meta["denoise"] is True and clean.meta["multitone"] == 3
    assert _roughness(clean.train[0]) < 0.7 * _roughness(noisy.train[0])
    plain = render_dataset(strands, tmp_path / "p", views=2, res=32, engine="cycles", samples=2, denoise=True)
    hair = plain.train[0].image[..., 3] > 0.5
    assert np.abs(clean.train[0].image[..., :3] - plain.train[0].image[..., :3])[hair].mean() > 0.03
