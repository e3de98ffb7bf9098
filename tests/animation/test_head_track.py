"""A head track read from a USD or Alembic file's animated transform: frames, rate, units, axes, and the
files it refuses."""

from __future__ import annotations

import subprocess
from dataclasses import replace

import numpy as np
import pytest
from head_helpers import write_xform_track

from cghair_format.animation.track_file import head_track_from_file, track_from_matrices
from cghair_format.animation.tracks import axis_rotation
from cghair_format.errors import CghError
from cghair_format.examples import example_asset
from cghair_format.exchange._common import StrandFileError
from cghair_format.exchange.xform_track import load_xforms

pytest.importorskip("pxr", reason="needs usd-core: pip install -e '.[usd]'")

FRAMES = 6
Y = np.array([0.0, 1.0, 0.0])


@pytest.fixture(scope="module")
def asset():
    return example_asset()  # y up, 1 m a unit


def _motion(frames: int = FRAMES) -> tuple[np.ndarray, np.ndarray]:
    """A head turning about y and tilting about x while it moves: rotations ``[F, 3, 3]``, translations ``[F, 3]``."""
    rotation = np.stack([axis_rotation(np.array([1.0, 0.0, 0.0]), 0.1 * f) @ axis_rotation(Y, 0.25 * f)
                         for f in range(frames)])
    translation = np.stack([[12.0 * f, 3.0 - f, -4.0 + 0.5 * f * f] for f in range(frames)])
    return rotation, translation


def _relative(rotation, translation, offset=(0.0, 0.0, 0.0)):
    """``W_f W_0^-1`` of the world transforms ``x -> R x + t + offset``."""
    offset = np.asarray(offset)
    r = rotation @ rotation[0].T
    return r, translation + offset - (r @ (translation[0] + offset)[:, None])[..., 0]


def test_a_usd_track_round_trips_to_the_expected_head_track_in_the_assets_units(tmp_path, asset):
    rotation, translation = _motion()
    path = tmp_path / "head.usda"
    write_xform_track(path, rotation, translation, fps=25.0, first_code=10.0, meters_per_unit=0.01,
                      parent_offset=(50.0, 0.0, 0.0))  # centimetres, under a moved parent
    track = head_track_from_file(path, asset)
    r, t = _relative(rotation, translation, np.array([50.0, 0.0, 0.0]))
    assert track.frames == FRAMES and track.fps == pytest.approx(25.0) and track.start == pytest.approx(10 / 25)
    assert np.allclose(track.rotation, r, atol=1e-9) and np.allclose(track.rotation[0], np.eye(3))
    assert np.allclose(track.translation, t * 0.01, atol=1e-9)  # cm -> the asset's metres
    local = head_track_from_file(path, asset, prim="/rig/head", rest="local")
    assert np.allclose(local.rotation, rotation, atol=1e-9)
    assert np.allclose(local.translation, (translation + [50.0, 0, 0]) * 0.01, atol=1e-9)


def test_a_z_up_track_is_turned_into_a_y_up_assets_axes(tmp_path, asset):
    z = np.array([0.0, 0.0, 1.0])
    rotation = np.stack([axis_rotation(z, 0.3 * f) for f in range(4)])  # a turn about z-up's up
    translation = np.stack([[0.0, 0.0, 0.1 * f] for f in range(4)])  # rising along z-up's up
    path = tmp_path / "zup.usda"
    write_xform_track(path, rotation, translation, up_axis="Z")
    track = head_track_from_file(path, asset)
    assert np.allclose(track.rotation, np.stack([axis_rotation(Y, 0.3 * f) for f in range(4)]), atol=1e-9)
    assert np.allclose(track.translation, np.outer(0.1 * np.arange(4), Y), atol=1e-9)


def test_ambiguous_static_uneven_and_scaled_tracks_are_refused_in_one_line(tmp_path, asset):
    rotation, translation = _motion(4)
    two = tmp_path / "two.usda"
    write_xform_track(two, rotation, translation, others=("/rig/jaw",))
    with pytest.raises(StrandFileError, match=r"2 animated xformable prims \(/rig/head, /rig/jaw\).*--head-prim"):
        load_xforms(two)
    assert load_xforms(two, "/rig/jaw").prim == "/rig/jaw"
    with pytest.raises(StrandFileError, match="'/nowhere' is not an xformable prim"):
        load_xforms(two, "/nowhere")
    with pytest.raises(StrandFileError, match="not animated"):
        load_xforms(two, "/rig")
    uneven = tmp_path / "uneven.usda"
    write_xform_track(uneven, rotation, translation, codes=[1.0, 2.0, 3.0, 5.0])
    with pytest.raises(StrandFileError, match="uneven time codes"):
        load_xforms(uneven)
    scaled = tmp_path / "scaled.usda"
    write_xform_track(scaled, rotation, translation, scale=2.0)
    with pytest.raises(CghError, match="frame 0 is not rigid.*--head-rest first"):
        head_track_from_file(scaled, asset, rest="local")
    relative = head_track_from_file(scaled, asset)  # a constant scale cancels against the first frame
    assert np.allclose(relative.rotation, _relative(rotation, translation)[0], atol=1e-9)
    growing = np.eye(4)[None].repeat(3, 0)
    growing[2, 0, 0] = 1.5
    with pytest.raises(CghError, match=r"frame 2 is not rigid \(stretch 1..1.5\)"):
        track_from_matrices(growing, 30.0)
    for bad in (tmp_path / "head.txt", tmp_path / "missing.usda"):
        with pytest.raises(CghError, match=bad.name):
            load_xforms(bad)


@pytest.mark.blender
def test_an_alembic_track_written_by_blender_reads_back_through_blender(tmp_path, asset):
    from cghair_format.exchange.blender import BlenderNotFoundError, find_blender_python

    try:
        python = find_blender_python()
    except BlenderNotFoundError as exc:
        pytest.fail(f"{exc}. Deselect this test with -m 'not blender'.")
    rotation, translation = _motion(4)
    usd, abc = tmp_path / "head.usda", tmp_path / "head.abc"
    write_xform_track(usd, rotation, translation * 0.01, fps=24.0)
    script = ("import sys, bpy\nbpy.ops.wm.read_factory_settings(use_empty=True)\n"
              "assert bpy.ops.wm.usd_import(filepath=sys.argv[1]) == {'FINISHED'}\n"
              "assert bpy.ops.wm.alembic_export(filepath=sys.argv[2], start=1, end=4) == {'FINISHED'}\n")
    subprocess.run([python, "-c", script, str(usd), str(abc)], check=True, capture_output=True, timeout=300)
    track = head_track_from_file(abc, replace(asset, meters_per_unit=0.01))  # Alembic is metres: 100 cm units
    r, t = _relative(rotation, translation * 0.01)
    assert track.frames == 4 and track.fps == pytest.approx(24.0)
    assert np.allclose(track.rotation, r, atol=1e-5) and np.allclose(track.translation, t * 100, atol=1e-4)
    assert load_xforms(abc).prim == "/rig/head" and load_xforms(abc, "/rig/head").frames == 4  # as in the .abc
