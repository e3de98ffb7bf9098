"""``cgh reconstruct`` end to end on a small synthetic capture, resume, and bad input refused
before the long work."""

import json

import numpy as np
import pytest

from cghair_format.cli import main
from cghair_format.exchange import load_strands, save_strands
from cghair_format.synth import synthesize
from training.datasets.nerf import write_dataset
from training.datasets.read import read_dataset
from training.datasets.synthetic import render_dataset
from training.reconstruct.metrics import evaluate_strands


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("capture")
    gt = synthesize("short", n_strands=150, n_points=16, seed=3)
    render_dataset(gt, root / "ds", views=16, res=64)
    save_strands(gt, root / "gt.npz")
    return root


def _run(capture, tmp_path, *extra):
    out = tmp_path / "recon.npz"
    args = ["reconstruct", str(capture / "ds"), "-o", str(out), "--strands", "100", "--hull-resolution", "32",
            "--backend", "reference", *extra]
    return main(args), out


@pytest.mark.slow
def test_reconstructs_closer_than_straight_strands(capture, tmp_path, capsys):
    rc, out = _run(capture, tmp_path, "--refine-iters", "3", "--debug-dir", str(tmp_path / "dbg"))
    assert rc == 0, capsys.readouterr().err
    log = capsys.readouterr().out
    for stage in ("[orientation]", "[hull]", "[scalp]", "[growth]", "[refine]"):
        assert stage in log
    recon, gt = load_strands(out), load_strands(capture / "gt.npz")
    assert recon.count > 50
    report = json.loads(out.with_suffix(".recon.json").read_text())
    assert set(report["timings_s"]) >= {"hull", "growth", "refine"}
    assert (tmp_path / "dbg" / "hull.png").is_file() and list((tmp_path / "dbg").glob("orientation_*.png"))
    m = evaluate_strands(recon, gt)
    # straight strands of the same length from the same roots, pointing down: the baseline to beat
    arr = recon.to_array()
    length = np.linalg.norm(np.diff(arr, axis=1), axis=2).sum(1)
    t = np.linspace(0, 1, arr.shape[1])
    straight = arr[:, :1] + t[None, :, None] * length[:, None, None] * np.float32([0, -1, 0])
    from cghair_format.strands import Strands
    base = evaluate_strands(Strands.from_array(straight.astype(np.float32)), gt)
    print(m.summary(), base.summary(), sep="\n")
    assert m.position_error_mm < base.position_error_mm
    assert m.f1(4.0) > base.f1(4.0)


@pytest.mark.slow
def test_resume_skips_finished_stages(capture, tmp_path, capsys):
    rc, out = _run(capture, tmp_path, "--refine-iters", "0")
    assert rc == 0
    capsys.readouterr()
    rc, _ = _run(capture, tmp_path, "--refine-iters", "2", "--resume", str(out.with_suffix(".recon.npz")))
    assert rc == 0
    log = capsys.readouterr().out
    assert "[hull]" not in log and "[growth]" not in log and "[refine]" in log


def _one_line_error(capsys, *needles):
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    for n in needles:
        assert n in err, err


def test_no_masks_is_refused(capture, tmp_path, capsys):
    ds = read_dataset(capture / "ds")
    for v in ds.train + ds.test:
        v.image[..., 3] = 1.0
    write_dataset(tmp_path / "nomask", ds)
    assert main(["reconstruct", str(tmp_path / "nomask"), "-o", str(tmp_path / "r.npz")]) == 2
    _one_line_error(capsys, "no hair mask")


def test_camera_that_misses_the_hair_is_refused(capture, tmp_path, capsys):
    ds = read_dataset(capture / "ds")
    ds.train[2].camera.world_to_camera[:3, 3] += [0, 0, -100.0]  # behind the camera: an empty view
    ds.train[2].image[..., 3] = 0.0
    write_dataset(tmp_path / "miss", ds)
    assert main(["reconstruct", str(tmp_path / "miss"), "-o", str(tmp_path / "r.npz")]) == 2
    _one_line_error(capsys, "does not see the hair")


def test_bad_scalp_meshes_are_refused(capture, tmp_path, capsys):
    empty = tmp_path / "empty.obj"
    empty.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    rc, _ = _run(capture, tmp_path, "--scalp", str(empty))
    assert rc == 2
    _one_line_error(capsys, "no triangles")
    far = tmp_path / "far.obj"
    far.write_text("v 100 100 100\nv 101 100 100\nv 100 101 100\nf 1 2 3\n")
    rc, _ = _run(capture, tmp_path, "--scalp", str(far), "--refine-iters", "0")
    assert rc == 2
    _one_line_error(capsys, "not in the same frame")


def test_unwritable_format_is_refused_first(capture, tmp_path, capsys):
    assert main(["reconstruct", str(capture / "ds"), "-o", str(tmp_path / "r.cgh")]) == 2
    _one_line_error(capsys, "cannot write strands")


def _zigzag(strands) -> float:
    a = strands.to_array().astype(np.float64)
    return float(np.median(np.linalg.norm(a[:, 2:] - 2 * a[:, 1:-1] + a[:, :-2], axis=2)))


@pytest.mark.slow
def test_resume_with_another_smoothing_re_smooths_the_checkpointed_strands(capture, tmp_path, capsys):
    rc, out = _run(capture, tmp_path, "--refine-iters", "0", "--smooth", "0")
    assert rc == 0
    assert "[smooth]" not in capsys.readouterr().out
    rough = load_strands(out)
    rc, _ = _run(capture, tmp_path, "--refine-iters", "0", "--smooth", "20",
                 "--resume", str(out.with_suffix(".recon.npz")))
    assert rc == 0
    log = capsys.readouterr().out
    assert "[smooth] 20 mm" in log and "[growth]" not in log
    smooth = load_strands(out)
    assert smooth.count == rough.count and _zigzag(smooth) < 0.8 * _zigzag(rough)
    np.testing.assert_array_equal(smooth.to_array()[:, 0], rough.to_array()[:, 0])


def test_bad_smoothing_width_is_refused(capture, tmp_path, capsys):
    from training.reconstruct.hull import ReconstructError
    from training.reconstruct.pipeline import ReconstructConfig

    with pytest.raises(ReconstructError, match="smoothing width must be >= 0 mm"):
        ReconstructConfig(smooth_mm=-1.0).validate()
    with pytest.raises(SystemExit) as exc:
        main(["reconstruct", str(capture / "ds"), "-o", str(tmp_path / "r.npz"), "--smooth", "nan"])
    assert exc.value.code == 2
    assert "argument --smooth: must be a number >= 0" in capsys.readouterr().err
