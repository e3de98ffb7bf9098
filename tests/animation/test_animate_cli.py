"""``cgh animate``: a simulated head motion or a DCC tool's animated strands, written as the file's animation."""

from __future__ import annotations

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format.animation import frame_points
from cghair_format.cli import main
from cghair_format.examples import example_asset


@pytest.fixture
def rest_file(tmp_path):
    path = tmp_path / "rest.cgh"
    cgh.write(example_asset(), path, "high")
    return path


def test_a_simulated_motion_is_written_as_the_files_animation(rest_file, tmp_path, capsys):
    out = tmp_path / "moving.cgh"
    assert main(["animate", str(rest_file), "-o", str(out), "--motion", "shake", "--frames", "6", "--fps", "24"]) == 0
    printed = capsys.readouterr().out
    assert "6 frames at 24 fps (simulate shake)" in printed and "animation: 6 frames" in printed
    animation = cgh.read_animation(out)
    assert animation.frames == 6 and animation.fps == 24 and animation.source == "simulate shake"
    assert cgh.read_info(out)["profile"] == "high"  # the input's profile unless --profile says otherwise
    assert main(["info", str(out)]) == 0 and "ANIM" in capsys.readouterr().out


def test_animated_strands_from_a_usd_file_drive_the_cards(rest_file, tmp_path, capsys):
    pytest.importorskip("pxr", reason="needs usd-core: pip install -e '.[usd]'")
    moving, usd, fitted = tmp_path / "moving.cgh", tmp_path / "moving.usda", tmp_path / "fitted.cgh"
    assert main(["animate", str(rest_file), "-o", str(moving), "--motion", "nod", "--frames", "4"]) == 0
    assert main(["export", str(moving), "-o", str(usd)]) == 0  # the strands at every frame, as a DCC tool has them
    capsys.readouterr()
    assert main(["animate", str(moving), "--from", str(usd), "-o", str(fitted)]) == 0
    assert "fitted 4 frames" in capsys.readouterr().out
    asset, source, result = cgh.read(moving), cgh.read_animation(moving), cgh.read_animation(fitted)
    points = cgh.decode_points(asset)
    diag = float(np.linalg.norm(points.reshape(-1, 3).max(0) - points.reshape(-1, 3).min(0)))
    for f in range(4):
        err = np.linalg.norm(frame_points(asset, result, f) - frame_points(asset, source, f), axis=-1) / diag
        assert err.mean() < 1e-3


def test_a_head_track_from_usd_and_a_head_mesh_drive_the_simulation(rest_file, tmp_path, capsys):
    pytest.importorskip("pxr", reason="needs usd-core: pip install -e '.[usd]'")
    from head_helpers import sphere_mesh, write_obj, write_xform_track

    from cghair_format.animation.tracks import axis_rotation, head_of

    rotation = np.stack([axis_rotation(np.array([0.0, 1.0, 0.0]), 0.1 * f) for f in range(5)])
    track, mesh, out = tmp_path / "head.usda", tmp_path / "head.obj", tmp_path / "moving.cgh"
    write_xform_track(track, rotation, np.zeros((5, 3)), fps=25.0, first_code=0.0, meters_per_unit=0.01)
    head = head_of(cgh.read(rest_file))
    write_obj(mesh, *sphere_mesh(head.radius, head.centre, 12))
    argv = ["animate", str(rest_file), "-o", str(out), "--head-track", str(track), "--collider", str(mesh)]
    assert main([*argv, "--substeps", "2"]) == 0
    printed = capsys.readouterr().out
    assert "head track: 5 frames at 25 fps" in printed and "collider " in printed and "distance field" in printed
    animation = cgh.read_animation(out)
    assert animation.frames == 5 and animation.fps == 25 and animation.source == "simulate head.usda"
    spine = animation.spine[-1].astype(np.float64)  # the last frame turned the head 0.4 rad about y
    rest = cgh.read(rest_file).cards.spine.astype(np.float64)
    assert np.allclose(spine[:, 0], rest[:, 0] @ rotation[-1].T, atol=1e-5)  # the roots ride the track


@pytest.mark.parametrize("argv, message", [
    (["--from", "x.usda", "--wind", "1,0,0"], "drop --motion and --wind"),
    (["--from", "missing.usda"], "missing.usda"),
    (["--from", "x.usda", "--collider", "head.obj"], "drop --collider"),
    (["--head-track", "x.usda", "--frames", "4"], "drop --frames and --fps"),
    (["--head-prim", "/head"], "--head-prim names the head in a --head-track file"),
    (["--head-track", "missing.usda"], "missing.usda: no such file"),
    (["--motion", "nod", "--collider", "head.stl"], "cannot read a mesh from .stl"),
])
def test_bad_requests_get_one_line_and_exit_2(rest_file, tmp_path, capsys, argv, message):
    assert main(["animate", str(rest_file), "-o", str(tmp_path / "o.cgh"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "o.cgh").exists()


@pytest.mark.parametrize("argv", [["--wind", "1,2"], ["--stiffness", "2"], ["--motion", "dance"]])
def test_bad_options_are_refused_by_the_parser(rest_file, tmp_path, argv):
    with pytest.raises(SystemExit) as exit_:
        main(["animate", str(rest_file), "-o", str(tmp_path / "o.cgh"), *argv])
    assert exit_.value.code == 2
