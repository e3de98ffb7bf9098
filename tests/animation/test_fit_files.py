"""Animated strands from files drive an asset: USD time-sampled BasisCurves written here with pxr, and
Alembic animated curves (made from them by Blender, read back through Blender)."""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from fit_helpers import known_animation, write_usd_cache

from cghair_format.animation import frame_points
from cghair_format.animation.fit import FitError, animation_from_file
from cghair_format.errors import CghError
from cghair_format.examples import example_asset, with_point_counts
from cghair_format.exchange._common import StrandFileError, UnsupportedFormatError
from cghair_format.exchange.strand_cache import load_cache

pytest.importorskip("pxr", reason="the USD tests need usd-core: pip install 'cghair[usd]'")


@pytest.fixture(scope="module")
def asset():
    return with_point_counts(example_asset(seed=5, strands=120, points=12, cards=6, segments=5), seed=2)


@pytest.fixture(scope="module")
def truth(asset):
    return known_animation(asset, 4)


@pytest.fixture
def usd(tmp_path, asset, truth):
    path = tmp_path / "anim.usda"
    write_usd_cache(path, [frame_points(asset, truth, f) for f in range(4)], asset.counts, fps=24.0, first_code=10)
    return path


def test_usd_time_samples_drive_the_asset(asset, truth, usd):
    fit, res = animation_from_file(asset, usd, refine=2)
    assert fit.frames == 4 and fit.fps == 24.0 and fit.start == pytest.approx(10 / 24)
    assert fit.source == "fit anim.usda"
    assert res.max[0] < 1e-6 and res.max.max() < 5e-3  # as fit_frames on the same points (test_fit)


def test_a_cache_in_centimetres_drives_an_asset_in_metres(tmp_path, asset, truth):
    frames = [100 * frame_points(asset, truth, f) for f in range(2)]
    write_usd_cache(tmp_path / "cm.usda", frames, asset.counts, fps=30.0, meters_per_unit=0.01)
    _, res = animation_from_file(asset, tmp_path / "cm.usda")
    assert res.max[0] < 1e-6


def test_the_cache_reads_every_frame_as_written(asset, truth, usd):
    cache = load_cache(usd)
    assert cache.frames == 4 and (cache.counts == asset.counts).all()
    frames = list(cache.padded(asset.points_per_strand))
    real = asset.real_points()
    assert np.array_equal(frames[3][real], frame_points(asset, truth, 3)[real].astype(np.float64))


def test_strand_ids_pick_the_asset_strands_from_a_larger_cache(tmp_path, asset, truth):
    extra = 7
    ids = (np.arange(asset.n_strands) + extra).astype(np.uint32)  # the cache has 7 other strands first
    mapped = replace(asset, strand_ids=ids)
    frames = [np.concatenate([np.zeros((extra, asset.points_per_strand, 3), np.float32),
                              frame_points(asset, truth, f)]) for f in range(2)]
    counts = np.r_[np.full(extra, 3), asset.counts]
    write_usd_cache(tmp_path / "more.usda", frames, counts, fps=30.0)
    _, res = animation_from_file(mapped, tmp_path / "more.usda")
    assert res.max[0] < 1e-6


@pytest.mark.parametrize(("edit", "message"), [
    (lambda f, c: (f[:-1], c[:-1]), "has 119 curves, the asset 120 strands"),
    (lambda f, c: (f, np.where(np.arange(len(c)) == 4, c - 1, c)), "1 strands have other point counts"),
])
def test_a_cache_that_does_not_match_is_refused_in_one_line(tmp_path, asset, truth, edit, message):
    frames, counts = edit(np.stack([frame_points(asset, truth, f) for f in range(2)], 1), asset.counts)
    write_usd_cache(tmp_path / "bad.usda", list(np.swapaxes(frames, 0, 1)), counts, fps=30.0)
    with pytest.raises(FitError) as info:
        animation_from_file(asset, tmp_path / "bad.usda")
    assert message in str(info.value) and "\n" not in str(info.value)


def test_nan_and_uneven_frames_are_refused(tmp_path, asset, truth):
    frames = [frame_points(asset, truth, f) for f in range(3)]
    frames[1][5, 0] = np.nan
    write_usd_cache(tmp_path / "nan.usda", frames, asset.counts, fps=30.0)
    with pytest.raises(StrandFileError, match="frame 1 holds NaN or infinite points"):
        animation_from_file(asset, tmp_path / "nan.usda")
    write_usd_cache(tmp_path / "uneven.usda", frames[:1] * 3, asset.counts, fps=30.0, codes=[1.0, 2.0, 4.0])
    with pytest.raises(StrandFileError, match="uneven time codes"):
        animation_from_file(asset, tmp_path / "uneven.usda")


def test_other_files_are_refused(tmp_path, asset):
    with pytest.raises(UnsupportedFormatError, match="cannot read animated strands from .ply"):
        load_cache(tmp_path / "a.ply")
    with pytest.raises(StrandFileError, match="no such file"):
        load_cache(tmp_path / "missing.usd")
    (tmp_path / "junk.usda").write_text("#usda 1.0\n(\n")
    with pytest.raises(CghError):
        load_cache(tmp_path / "junk.usda")


TO_ALEMBIC = """
import sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
assert bpy.ops.wm.usd_import(filepath=sys.argv[1]) == {"FINISHED"}
assert bpy.ops.wm.alembic_export(filepath=sys.argv[2], start=int(sys.argv[3]), end=int(sys.argv[4])) == {"FINISHED"}
"""


@pytest.mark.blender
def test_alembic_animated_curves_drive_the_asset(tmp_path, asset, truth, usd):
    from cghair_format.exchange.blender import BlenderNotFoundError, find_blender_python

    try:
        python = find_blender_python()
    except BlenderNotFoundError as exc:
        pytest.fail(f"{exc}. Deselect this test with -m 'not blender'.")
    script = tmp_path / "to_abc.py"
    script.write_text(TO_ALEMBIC)
    abc = tmp_path / "anim.abc"
    subprocess.run([python, str(script), str(usd), str(abc), "10", "13"], check=True, capture_output=True,
                   timeout=300)
    fit, res = animation_from_file(asset, abc, refine=2)
    assert fit.frames == 4 and fit.fps == pytest.approx(24.0)
    assert res.max[0] < 1e-5 and res.max.max() < 5e-3
    assert Path(abc).exists()
