"""A point tolerance of one's own (``Profile.with_position_tolerance``, ``--point-tolerance`` of cgh encode,
cgh train and what cgh animate keeps): the writer holds the strand points within it, the file records it
(META ``quant.position_tolerance``, spec 7) and a file at a named profile's own bound is unchanged."""

import json

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format.cli import main
from cghair_format.examples import example_asset

COMPACT = cgh.PROFILES["compact"]


@pytest.fixture(scope="module")
def asset():
    return example_asset(5, strands=120, points=24)


def _largest_error(asset, data, report) -> float:
    """The decoded points' largest distance from the input's, as a fraction of the bbox diagonal."""
    ours = cgh.decode_points(report.in_file_order(asset))
    theirs = cgh.decode_points(cgh.decode(data))
    flat = ours.reshape(-1, 3)
    return float(np.linalg.norm(ours - theirs, axis=-1).max() / np.linalg.norm(flat.max(0) - flat.min(0)))


def test_a_looser_tolerance_codes_smaller_and_holds(asset):
    sizes = {}
    for fraction in (2e-4, 1e-3, 5e-3):
        data, report = cgh.encode(asset, COMPACT.with_position_tolerance(fraction))
        error = _largest_error(asset, data, report)
        assert error <= fraction and error > fraction / 4  # held, and used: the step grew with it
        info = cgh.read_info(data)
        assert info["points_within"] == fraction and info["profile"] == "compact"
        assert ("position_tolerance" in info["quant"]) == (fraction != COMPACT.position_tolerance)
        sizes[fraction] = info["chunks"][[c["type"] for c in info["chunks"]].index("STRD")]["stored_bytes"]
    assert sizes[5e-3] < sizes[1e-3] < sizes[2e-4]


def test_the_profiles_own_bound_writes_the_profiles_file(asset):
    """Asked for compact's own 2e-4, the writer writes compact's file byte for byte: no record in META."""
    assert cgh.encode(asset, COMPACT.with_position_tolerance(2e-4))[0] == cgh.encode(asset, "compact")[0]
    assert COMPACT.with_position_tolerance(None) is COMPACT


@pytest.mark.parametrize("fraction", [0.0, -1e-3, 0.02, float("nan"), float("inf")])
def test_a_tolerance_out_of_range_is_refused_when_made(fraction):
    with pytest.raises(ValueError, match=r"fraction of the bounding-box diagonal in \(0, 0.01\]"):
        COMPACT.with_position_tolerance(fraction)


def test_the_lossless_profile_takes_no_tolerance():
    with pytest.raises(ValueError, match="stores points exactly"):
        cgh.PROFILES["lossless"].with_position_tolerance(1e-3)


def test_cgh_encode_point_tolerance(asset, tmp_path, capsys):
    source, out, again = tmp_path / "src.cgh", tmp_path / "loose.cgh", tmp_path / "again.cgh"
    cgh.write(asset, source, "lossless")
    assert main(["encode", str(source), "-o", str(out), "--point-tolerance", "1e-3"]) == 0
    assert "(bound 0.001)" in capsys.readouterr().out
    assert main(["info", str(out)]) == 0
    assert "points      within 0.001 of the bbox diagonal, step" in capsys.readouterr().out
    assert main(["validate", str(out)]) == 0
    assert "; points: within 0.001 of the bbox diagonal; opacities:" in capsys.readouterr().out
    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["points_within"] == 1e-3 and info["quant"]["position_tolerance"] == 1e-3
    assert main(["encode", str(out), "-o", str(again)]) == 0  # what a re-encoding is measured against
    assert "its decoded points, which already lie up to 0.001 of the bbox diagonal" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "says"), [
    (["--point-tolerance", "0"], "must be a fraction of the bounding-box diagonal in (0, 0.01]"),
    (["--point-tolerance", "0.5"], "must be a fraction of the bounding-box diagonal in (0, 0.01]"),
    (["--point-tolerance", "tiny"], "must be a number"),
    (["--point-tolerance", "1e-3", "--profile", "lossless"], "--point-tolerance: profile 'lossless' stores points "
                                                              "exactly"),
])
def test_cgh_encode_refuses_a_tolerance_it_cannot_follow(asset, tmp_path, capsys, argv, says):
    source = tmp_path / "src.cgh"
    cgh.write(asset, source, "lossless")
    try:
        code = main(["encode", str(source), "-o", str(tmp_path / "out.cgh"), *argv])
    except SystemExit as exc:  # argparse's refusals
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2
    assert says in err.splitlines()[-1]  # one line (after argparse's usage)
    assert not (tmp_path / "out.cgh").exists()


def test_cgh_animate_keeps_the_inputs_tolerance(tmp_path):
    rest, moving = tmp_path / "rest.cgh", tmp_path / "moving.cgh"
    cgh.write(example_asset(), rest, COMPACT.with_position_tolerance(2e-3))
    assert main(["animate", str(rest), "-o", str(moving), "--motion", "nod", "--frames", "3"]) == 0
    assert cgh.read_info(moving)["points_within"] == 2e-3
