"""The quantizers alone: exact inverses and their error bounds."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cghair_format.quantize import (
    bfloat16_decode,
    hier_decode,
    hier_encode,
    level_plan,
    oct_decode,
    oct_encode,
    rows_int8_decode,
    rows_int8_encode,
    unzigzag,
    zigzag,
)


@given(st.lists(st.integers(-2**62, 2**62), min_size=1, max_size=50))
def test_zigzag_is_exact_inverse(values):
    x = np.array(values, np.int64)
    assert (unzigzag(zigzag(x)) == x).all()
    assert (zigzag(x) >= 0).all()


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 130), stride=st.sampled_from([1, 2, 4, 16, 64]), seed=st.integers(0, 10**6),
       scale=st.floats(0.1, 1e5))
def test_hierarchical_coder_is_within_half_a_step(n, stride, seed, scale):
    rng = np.random.default_rng(seed)
    y = np.cumsum(rng.normal(size=(5, n)), axis=1) * scale
    base, levels = hier_encode(y, stride)
    rec = hier_decode(base, levels, n, stride)
    assert np.abs(rec - y).max() <= 0.5 + 1e-9 * scale
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


def test_hierarchical_coder_zeroes_smooth_curves():
    t = np.linspace(0, 1, 100)
    y = 400 * np.sin(2 * t)[None, :]  # smooth: refinement residuals vanish
    _, levels = hier_encode(y, 16)
    assert np.mean(np.concatenate(levels, axis=1) == 0) > 0.9


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10**6))
def test_octahedral_normals_within_bound(seed):
    n = np.random.default_rng(seed).normal(size=(500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    back = oct_decode(oct_encode(n, 16), 16)
    # octahedral quantization at b bits: angular error below ~2 / (2^(b-1) - 1) radians
    assert np.abs(back - n).max() < 2.0 / (2**15 - 1)
    assert np.allclose(np.linalg.norm(back, axis=1), 1.0)


@pytest.mark.parametrize("bits", [8, 6, 4])
def test_int8_rows_error_is_half_a_step_per_row(bits):
    w = np.random.default_rng(0).normal(size=(40, 30))
    q, scale_bits = rows_int8_encode(w, bits)
    top = (1 << (bits - 1)) - 1
    scale = bfloat16_decode(scale_bits)
    assert q.dtype == np.int8 and scale_bits.dtype == np.uint16 and scale.shape == (40,)
    # the bfloat16 scale is the exact one rounded up by less than 2^-7, so no value leaves the levels
    exact = np.abs(w).max(axis=1) / top
    assert (scale >= exact).all() and (scale <= exact * (1 + 2**-7)).all() and np.abs(q).max() <= top
    err = np.abs(rows_int8_decode(q, scale_bits) - w)
    assert (err <= scale[:, None] / 2 + 1e-6).all()
