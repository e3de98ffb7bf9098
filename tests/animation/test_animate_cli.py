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


@pytest.mark.parametrize("argv, message", [
    (["--from", "x.usda", "--wind", "1,0,0"], "drop --motion and --wind"),
    (["--from", "missing.usda"], "missing.usda"),
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
