"""``cghair_format.smooth``: a rough strand comes out smoother with its root and length kept, a smooth
bend much longer than the filter stays, and bad widths are refused in one line (API and CLI)."""

import numpy as np
import pytest

from cghair_format.cli import main
from cghair_format.errors import AssetError
from cghair_format.exchange import load_strands, save_strands
from cghair_format.smooth import smooth_strands
from cghair_format.strands import Strands

MM = 0.001  # metres per unit: coordinates in millimetres


def _lengths(a: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(a, axis=1), axis=2)


def _zigzag(a: np.ndarray) -> float:
    """Median |second difference| over every inner point of strands ``[S, P, 3]``."""
    return float(np.median(np.linalg.norm(a[:, 2:] - 2 * a[:, 1:-1] + a[:, :-2], axis=2)))


def _rough(n_strands: int = 20, n_points: int = 32, seed: int = 0) -> np.ndarray:
    """Strands hanging down in 5 mm steps, with 1 mm point-to-point jitter and a gentle 200 mm arc."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_points) * 5.0
    arc = np.stack([40 * np.sin(t / 200), -t, np.zeros_like(t)], -1)
    pts = arc[None] + rng.normal(0, 1.0, (n_strands, n_points, 3))
    pts[:, 0] = arc[0]
    return pts + rng.uniform(-50, 50, (n_strands, 1, 3))


def test_rough_strands_come_out_smoother_with_root_and_length_kept():
    pts = _rough()
    out = smooth_strands(Strands.from_array(pts.astype(np.float32), meters_per_unit=MM), 6.0).to_array()
    assert _zigzag(out) < 0.3 * _zigzag(pts)
    np.testing.assert_array_equal(out[:, 0], pts[:, 0].astype(np.float32))
    # each strand's length kept and its points equally spaced, up to the chords of the resampling
    # (equal steps along the smoothed curve, whose bends the chords cut: 1 % here, 2 % at most)
    np.testing.assert_allclose(_lengths(out).sum(1), _lengths(pts).sum(1), rtol=5e-3)
    seg = _lengths(out)
    np.testing.assert_allclose(seg, np.repeat(seg.mean(1, keepdims=True), 31, 1), rtol=2e-2)


def test_a_bend_much_longer_than_the_filter_stays():
    t = np.linspace(0, np.pi, 64)
    arc = (np.stack([np.sin(t), -np.cos(t) + 1, np.zeros_like(t)], -1) * 100.0)[None]  # r = 100 mm, 5 mm steps
    out = smooth_strands(Strands.from_array(arc.astype(np.float32), meters_per_unit=MM), 3.0).to_array()
    # the tip of a half circle of radius 100 mm moves by well under a millimetre
    assert np.linalg.norm(out[0, -1] - arc[0, -1]) < 1.0
    assert np.abs(out - arc).max() < 1.0


def test_width_is_in_millimetres_by_the_strands_units():
    pts = _rough().astype(np.float32)
    in_mm = smooth_strands(Strands.from_array(pts, meters_per_unit=MM), 6.0).to_array()
    in_cm = smooth_strands(Strands.from_array(pts / 10, meters_per_unit=0.01), 6.0).to_array()
    np.testing.assert_allclose(in_cm * 10, in_mm, atol=1e-3)


def test_zero_width_is_the_identity_and_mixed_counts_are_filtered():
    s = Strands(np.float32(_rough(2, 10).reshape(-1, 3)), np.array([0, 3, 20], np.int64), meters_per_unit=MM)
    assert smooth_strands(s, 0) is s
    out = smooth_strands(s, 6.0)
    np.testing.assert_array_equal(out.offsets, s.offsets)
    assert not np.allclose(out.points[3:], s.points[3:])  # the 17-point strand moved, its root did not
    np.testing.assert_array_equal(out.points[[0, 3]], s.points[[0, 3]])


def test_a_strand_of_zero_length_stays_as_it_is():
    pts = np.concatenate([np.zeros((1, 8, 3)), _rough(1, 8)]).astype(np.float32)
    out = smooth_strands(Strands.from_array(pts, meters_per_unit=MM), 6.0).to_array()
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[0], pts[0])


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "wide"])
def test_bad_widths_are_refused(bad):
    with pytest.raises(AssetError, match="smoothing width"):
        smooth_strands(Strands.from_array(np.float32(_rough(1)), meters_per_unit=MM), bad)


def test_convert_smooth_on_an_existing_file(tmp_path, capsys):
    src = tmp_path / "rough.npz"
    save_strands(Strands.from_array(np.float32(_rough()), meters_per_unit=MM), src)
    assert main(["convert", str(src), str(tmp_path / "smooth.npz"), "--smooth", "6"]) == 0
    assert _zigzag(load_strands(tmp_path / "smooth.npz").to_array()) < 0.3 * _zigzag(_rough())
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:  # argparse refuses it: usage line and one error line
        main(["convert", str(src), str(tmp_path / "x.npz"), "--smooth", "-2"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "argument --smooth: must be a number >= 0" in err[-1], err
