"""The quantizers alone: exact inverses and their error bounds."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cghair_format.geometry import angle_normals, normal_angles, spine_frames
from cghair_format.quantize import (
    BIAS_STEP_DIVISOR,
    COLOUR_BASIS,
    from_colour_basis,
    hier_decode,
    hier_encode,
    level_plan,
    to_colour_basis,
    unzigzag,
    weight_steps,
    weights_decode,
    weights_encode,
    zigzag,
)


@given(st.lists(st.integers(-2**63, 2**63 - 1), min_size=1, max_size=50))
def test_zigzag_is_exact_inverse(values):
    """Over the whole int64 range (its ends are where a shift would overflow): 0, -1, 1, -2 ... map to
    0, 1, 2, 3 ... (Python's integers, which do not overflow, are the oracle) and back."""
    x = np.array(values, np.int64)
    assert zigzag(x).tolist() == [2 * v if v >= 0 else -2 * v - 1 for v in values]
    assert (unzigzag(zigzag(x)) == x).all()


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 130), stride=st.sampled_from([1, 2, 4, 16, 64]), seed=st.integers(0, 10**6),
       scale=st.floats(0.1, 1e5))
def test_hierarchical_coder_is_within_half_a_step(n, stride, seed, scale):
    rng = np.random.default_rng(seed)
    y = np.cumsum(rng.normal(size=(5, n)), axis=1) * scale
    base, levels, encoded = hier_encode(y, stride)
    rec = hier_decode(base, levels, n, stride)
    assert np.abs(rec - y).max() <= 0.5 + 1e-9 * scale
    assert np.array_equal(encoded, rec)  # the writer's reconstruction is the reader's
    base_idx, plan = level_plan(n, stride)
    assert len(base_idx) + sum(len(idx) for idx, _, _ in plan) == n  # every sample coded exactly once


@pytest.mark.parametrize("taps", [(2, 2, 2, 2), (4, 4, 4, 4), (6, 6, 6, 6), (8, 8, 8, 8), (2, 6, 6, 4)])
def test_level_interpolation_is_exact_on_polynomials_of_its_degree(taps):
    """A level of width T interpolates through T neighbours (spec 4.1), T/2 a side where the strand has
    them: exact on polynomials of degree T - 1 wherever it has all T."""
    n = 100
    base, levels = level_plan(n, 16, taps)
    x = np.arange(n, dtype=np.float64) / n
    known = set(base.tolist())
    for t, (idx, nb, wt) in zip(taps, levels, strict=True):
        used = (wt != 0).sum(axis=1)
        assert used.max() == t and set(nb[wt != 0].tolist()) <= known  # only samples decoded before
        known |= set(idx.tolist())
        full = used == t
        assert full.any()
        for degree in range(t):
            y = x**degree
            assert np.allclose((y[nb] * wt).sum(axis=1)[full], y[idx][full], atol=1e-9)
        left = np.where(wt != 0, nb < idx[:, None], False).sum(axis=1)
        assert (left[full] == t // 2).all()
    assert level_plan(n, 16, None)[1][0][1].shape[1] == 4
    for (_, nb4, wt4), (_, nb, wt) in zip(level_plan(n, 16)[1], level_plan(n, 16, (4,) * 4)[1], strict=True):
        assert np.array_equal(nb4, nb) and np.array_equal(wt4, wt)


@pytest.mark.parametrize("taps", [(4, 4, 4), (4, 4, 4, 4, 4), (4, 4, 4, 3), (4, 4, 4, 10), (0, 4, 4, 4)])
def test_level_plan_refuses_widths_that_do_not_fit(taps):
    with pytest.raises(ValueError, match="do not fit"):
        level_plan(100, 16, taps)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 130), stride=st.sampled_from([2, 8, 16]), seed=st.integers(0, 10**6))
def test_lowerable_samples_land_between_the_floor_and_their_own_value(n, stride, seed):
    """Marked samples may come out anywhere in [floor, y + 0.5], the others within half a step, and
    the reader's reconstruction is still the writer's; marking everything codes nothing but zeros."""
    rng = np.random.default_rng(seed)
    y = rng.uniform(0, 31.5, size=(6, n))
    lowerable = rng.random(y.shape) < 0.7
    base, levels, encoded = hier_encode(y, stride, lowerable)
    rec = hier_decode(base, levels, n, stride)
    assert np.array_equal(encoded, rec)
    assert (np.abs(rec - y)[~lowerable] <= 0.5 + 1e-9).all()
    assert (rec[lowerable] >= -0.5 - 1e-9).all() and (rec[lowerable] <= y[lowerable] + 0.5 + 1e-9).all()
    all_marked = hier_encode(y, stride, np.ones_like(lowerable))
    assert not all_marked[0].any() and not any(r.any() for r in all_marked[1])  # every residual zero
    exact, none_marked = hier_encode(y, stride), hier_encode(y, stride, np.zeros_like(lowerable))
    assert np.array_equal(none_marked[2], exact[2])  # nothing marked: the plain coder's output


def test_hierarchical_coder_zeroes_smooth_curves():
    t = np.linspace(0, 1, 100)
    y = 400 * np.sin(2 * t)[None, :]  # smooth: refinement residuals vanish
    _, levels, _ = hier_encode(y, 16)
    assert np.mean(np.concatenate(levels, axis=1) == 0) > 0.9


def _twisting_cards(seed: int, cards: int = 5, points: int = 33):
    """Spines that wander and turn, with unit normals across them that twist along each card."""
    rng = np.random.default_rng(seed)
    spine = np.cumsum(rng.normal(size=(cards, points, 3)) * 0.2 + [0.0, 0.0, 1.0], axis=1)
    t, r = spine_frames(spine)
    twist = np.cumsum(rng.normal(size=(cards, points)) * 0.5, axis=1)[..., None]
    return spine, np.cos(twist) * r + np.sin(twist) * np.cross(t, r)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10**6), bits=st.integers(8, 24))
def test_normal_angles_within_bound(seed, bits):
    spine, normal = _twisting_cards(seed)
    t, r = spine_frames(spine)
    # the frames: unit tangents, unit references across them
    assert np.allclose(np.linalg.norm(r, axis=-1), 1) and np.abs(np.sum(r * t, axis=-1)).max() < 1e-9
    angle = normal_angles(normal, spine, bits)
    # unwrapped: neighbouring angles less than half a turn apart, so interpolating them is meaningful
    assert np.abs(np.diff(angle, axis=1)).max() < 2 ** (bits - 1)
    back = angle_normals(np.rint(angle), spine, bits)
    # rounding to 2^bits steps a turn: at most half a step, pi / 2^bits rad
    err = np.arccos(np.clip(np.sum(back * normal, axis=-1), -1, 1))
    assert err.max() <= np.pi / 2**bits * (1 + 1e-6) + 1e-7
    assert np.allclose(np.linalg.norm(back, axis=-1), 1) and np.abs(np.sum(back * t, axis=-1)).max() < 1e-9


def test_normal_angles_survive_a_tangent_along_the_carried_reference():
    # t_0 = z gives r_0 = normalize(x cross z) = -y; the spine then doubles back so that t_1 = -y, along
    # r_0: nothing of r_0 is left across t_1, and the axis rule gives r_1 = normalize(x cross -y) = -z
    spine = np.array([[[0, 0, 0], [0, 0, 1], [0, -1, 0]]], np.float64)
    t, r = spine_frames(spine)
    assert np.allclose(t[0, 1], [0, -1, 0]) and np.allclose(r[0, :2], [[0, -1, 0], [0, 0, -1]])
    assert np.abs(np.sum(r * t, axis=-1)).max() < 1e-9
    normal = np.cross(t, r)
    assert np.allclose(angle_normals(np.rint(normal_angles(normal, spine, 8)), spine, 8), normal, atol=1e-12)


def test_colour_basis_is_orthonormal_and_exact_inverse():
    assert np.allclose(COLOUR_BASIS @ COLOUR_BASIS.T, np.eye(3), atol=1e-15)
    rows = np.random.default_rng(0).normal(size=(12, 5))
    assert np.allclose(from_colour_basis(to_colour_basis(rows)), rows, atol=1e-13)
    # grey triples (R = G = B) have only the first basis row
    grey = np.repeat(np.random.default_rng(1).normal(size=(4, 1, 5)), 3, axis=1).reshape(12, 5)
    assert np.abs(to_colour_basis(grey).reshape(4, 3, 5)[:, 1:]).max() < 1e-12


def test_mlp_layers_take_their_own_fraction():
    """The codebooks' step follows ``fraction``, each MLP layer's ``mlp_fraction`` (the compact profile
    stores the MLP coarser than the codebooks)."""
    rng = np.random.default_rng(2)
    codebooks = rng.normal(size=(3, 4, 8))
    layers = [(rng.normal(size=(8, 8)), rng.normal(size=8)), (rng.normal(size=(12, 8)) * 0.1, rng.normal(size=12))]
    same, apart = weight_steps(codebooks, layers, 0.35), weight_steps(codebooks, layers, 0.35, 0.7)
    assert apart[0] == same[0] and np.allclose(apart[1:], 2 * np.asarray(same[1:]), rtol=1e-6)


@pytest.mark.parametrize("fraction", [0.02, 0.35, 1.0])
def test_weights_within_their_steps(fraction):
    rng = np.random.default_rng(0)
    codebooks = rng.normal(size=(3, 4, 8))
    layers = [(rng.normal(size=(8, 8)), rng.normal(size=8)), (rng.normal(size=(12, 8)) * 0.1, rng.normal(size=12))]
    steps = weight_steps(codebooks, layers, fraction)
    # a fraction of each array's RMS (the last layer's in the colour basis, whose RMS is the same)
    for step, w in zip(steps, [codebooks] + [w for w, _ in layers], strict=True):
        assert np.isclose(step, fraction * np.sqrt(np.mean(w**2)), rtol=1e-6)
    qc, coded = weights_encode(steps, codebooks, layers)
    cb, decoded = weights_decode(steps, qc, coded)
    assert cb.dtype == np.float32 and np.abs(cb - codebooks).max() <= steps[0] / 2 * (1 + 1e-6)
    (w0, b0), (w1, b1) = decoded
    assert np.abs(w0 - layers[0][0]).max() <= steps[1] / 2 * (1 + 1e-6)
    assert np.abs(b0 - layers[0][1]).max() <= steps[1] / BIAS_STEP_DIVISOR / 2 * (1 + 1e-6)
    # the last layer's errors, half a step in the basis, reach RGB through its columns
    reach = np.abs(COLOUR_BASIS).sum(axis=0).max() / 2
    assert np.abs(w1 - layers[1][0]).max() <= reach * steps[2] * (1 + 1e-6)
    assert np.abs(b1 - layers[1][1]).max() <= reach * steps[2] / BIAS_STEP_DIVISOR * (1 + 1e-6)
    # and the error of a row triple, as a vector, is the basis's: at most half a step per row
    assert np.linalg.norm((w1 - layers[1][0]).reshape(4, 3, 8), axis=1).max() <= np.sqrt(3) / 2 * steps[2] * (1 + 1e-6)
