"""Cards fitted to animated strands (cghair_format.animation.fit): exact recovery of a known motion,
noise, cards their strands do not determine, strand order and point counts, and the refusals."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from fit_helpers import bent, known_animation

from cghair_format.animation import Animation, frame_points
from cghair_format.animation.fit import FitError, fit_frames, residual_lines
from cghair_format.animation.tracks import axis_rotation
from cghair_format.asset import Cards
from cghair_format.examples import example_asset, with_point_counts
from cghair_format.geometry import bounding_diagonal, spine_tangents


@pytest.fixture(scope="module")
def asset():
    return example_asset(seed=3, strands=160, points=16, cards=8, segments=6)


def _frames(asset, animation):
    return [frame_points(asset, animation, f) for f in range(animation.frames)]


def _fit_error(asset, fit: Animation, frames) -> float:
    """The largest distance from a given point to the fitted cards' point, over the bbox diagonal."""
    diag = bounding_diagonal(frames[0])
    return max(float(np.linalg.norm(frame_points(asset, fit, f) - frames[f], axis=-1).max()) / diag
               for f in range(fit.frames))


def test_a_known_motion_is_recovered(asset):
    truth = known_animation(asset, 4)
    fit, res = fit_frames(asset, _frames(asset, truth), fps=truth.fps)
    diag = bounding_diagonal(truth.spine)
    # the frames are float32 points (1e-7 of the diagonal); the strips come back to a few times that
    assert np.abs(fit.spine - truth.spine).max() / diag < 1e-6
    assert np.abs(fit.normal - truth.normal).max() < 1e-5
    assert res.max.max() < 1e-6 and res.mean.max() < 1e-7
    assert fit.fps == truth.fps and fit.frames == 4
    fit.validate(asset.cards)


def test_noise_is_averaged_not_followed(asset):
    truth = known_animation(asset, 3)
    clean = _frames(asset, truth)
    sigma = 1e-3 * bounding_diagonal(clean[0])
    rng = np.random.default_rng(0)
    noisy = [c + rng.normal(0, sigma, c.shape) for c in clean]
    fit, res = fit_frames(asset, noisy)
    # a point's noise is sigma a coordinate, 1.6 sigma long on average: the residual is that, and the
    # fitted cards decode within a fraction of it of the clean points (each card fits ~20 strands)
    diag = bounding_diagonal(clean[0])
    assert 1.2 < res.mean.min() * diag / sigma and res.mean.max() * diag / sigma < 1.8
    mean_clean = np.mean([np.linalg.norm(frame_points(asset, fit, f) - clean[f], axis=-1).mean()
                          for f in range(3)])
    assert mean_clean < 0.5 * sigma
    assert _fit_error(asset, fit, clean) < 6 * sigma / diag


def test_cards_without_enough_strands_follow_their_strands_rigidly(asset):
    # strands only on cards 0-5, card 6 with one strand, card 7 with none: a rigid turn moves them all
    keep = np.flatnonzero(asset.strand_card < 6)
    one = np.flatnonzero(asset.strand_card == 6)[:1]
    sparse = asset.take_strands(np.r_[keep, one]).validate()
    truth = Animation.of_frames([asset.cards, bent(asset.cards, 0.5, 0.0)], fps=30.0)
    fit, res = fit_frames(sparse, _frames(sparse, truth))
    diag = bounding_diagonal(truth.spine)
    assert np.abs(fit.spine - truth.spine).max() / diag < 1e-6
    assert np.abs(fit.normal - truth.normal).max() < 3e-5  # float32 points 1e-7 apart on a strip 0.02 wide
    assert res.max.max() < 1e-6


def test_variable_point_counts_fit_their_own_points(asset):
    short = with_point_counts(asset, seed=1)
    truth = known_animation(short, 3)
    frames = _frames(short, truth)
    for f in frames:  # what a placeholder holds must not matter
        f[~short.real_points()] = 1e6
    # the cut strands leave the ends of some cards without points: those stay as the rigid fit carries
    # them, and the tangent at the last points they reach depends on them; the linear fit leaves points
    # there 6e-2 of the diagonal off, two Gauss-Newton steps 2e-3 (four: 4e-4)
    _, linear = fit_frames(short, frames)
    assert linear.max[0] < 1e-6 and linear.max.max() > 3e-2
    _, res = fit_frames(short, frames, refine=2)
    assert res.max[0] < 1e-6 and res.max.max() < 5e-3 and res.mean.max() < 2e-5


def _kinked(cards: Cards, angle: float) -> Cards:
    """``cards`` with every spine point past the second turned by ``angle`` about the second, across the
    card: the part past the bend moves rigidly, and differently from the card as a whole."""
    spine, normal = cards.spine.astype(np.float64), cards.normal.astype(np.float64)
    for c in range(cards.count):
        axis = np.cross(spine[c, 2] - spine[c, 1], normal[c, 1])
        rot = axis_rotation(axis / np.linalg.norm(axis), angle)
        spine[c, 2:] = (spine[c, 2:] - spine[c, 1]) @ rot.T + spine[c, 1]
        normal[c, 2:] = normal[c, 2:] @ rot.T
    t = spine_tangents(spine)  # (the normal at the bend, made perpendicular to its new tangent)
    normal -= (normal * t).sum(-1, keepdims=True) * t
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return Cards(spine.astype(np.float32), normal.astype(np.float32), cards.half_width, cards.group)


def test_a_tail_past_the_strands_follows_the_part_next_to_it(asset):
    """Strands reach three quarters of their cards; the cards bend near the root. The tail past the
    strands' ends moves with the bent part, not with the whole card (whose rigid fit turns half as far):
    carried with the whole card, it folded the tip back, 5e-3 of the diagonal off at the points."""
    uvd = asset.uvd.copy()
    uvd[..., 0] *= 0.75
    short = replace(asset, uvd=uvd)
    truth = Animation.of_frames([short.cards, _kinked(short.cards, 0.5), _kinked(short.cards, 1.0)], fps=30.0)
    fit, res = fit_frames(short, _frames(short, truth))
    assert res.max.max() < 1e-4
    assert np.abs(fit.spine - truth.spine).max() / bounding_diagonal(truth.spine) < 1e-3


def test_strand_ids_map_the_source_order(asset):
    rng = np.random.default_rng(2)
    ids = rng.permutation(asset.n_strands + 5)[:asset.n_strands].astype(np.uint32)
    mapped = replace(asset, strand_ids=ids)
    truth = known_animation(asset, 2)
    source = []
    for f in _frames(asset, truth):
        s = np.zeros((asset.n_strands + 5, *f.shape[1:]), np.float32)
        s[ids] = f
        source.append(s)
    fit, res = fit_frames(mapped, source)
    assert res.max.max() < 1e-6
    with pytest.raises(FitError, match=f"has {asset.n_strands} strands, but the asset's strand ids reach"):
        fit_frames(mapped, [s[:asset.n_strands] for s in source])


@pytest.mark.parametrize(("change", "message"), [
    (lambda f: f[:-1], "frame 1 has 159 strands, the asset 160"),
    (lambda f: f[:, :-1], "frame 1 has 15 points a strand, the asset 16"),
    (lambda f: np.where(np.arange(len(f))[:, None, None] == 7, np.nan, f), "frame 1 holds NaN or infinite"),
    (lambda f: f[..., :2], "frame 1: strand points must be [strands, points, 3]"),
])
def test_mismatched_frames_are_refused_in_one_line(asset, change, message):
    good = frame_points(asset, Animation.of_frames([asset.cards], 30.0), 0)
    with pytest.raises(FitError) as info:
        fit_frames(asset, [good, change(good)])
    assert message in str(info.value) and "\n" not in str(info.value)


def test_no_frames_bad_rates_and_steps_are_refused_before_fitting(asset):
    with pytest.raises(FitError, match="no frames"):
        fit_frames(asset, [])
    for fps in (0.0, 1e9, np.nan):
        with pytest.raises(FitError, match="frame rate must lie in"):
            fit_frames(asset, iter(()), fps=fps)
    for refine in (-1, 17, 1.5):
        with pytest.raises(FitError, match="refine must be a whole number"):
            fit_frames(asset, iter(()), refine=refine)


def test_residual_lines_list_every_frame(asset):
    truth = known_animation(asset, 3)
    _, res = fit_frames(asset, _frames(asset, truth), fps=24.0)
    lines = residual_lines(res, 24.0, start=1.0)
    assert len(lines) == 5 and lines[2].split()[:2] == ["1", "1.042"]
    assert lines[-1].startswith("fitted 3 frames: point error mean")


def test_without_scipy_the_fit_says_what_to_install(asset, monkeypatch):
    import sys

    from cghair_format.errors import MissingDependencyError

    monkeypatch.setitem(sys.modules, "scipy.linalg", None)  # import scipy.linalg now raises ImportError
    with pytest.raises(MissingDependencyError, match=r"pip install 'cghair\[cards\]'"):
        fit_frames(asset, [])
