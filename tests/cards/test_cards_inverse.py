import numpy as np

from cghair_format.asset import Cards
from cghair_format.cards._util import project_to_spines
from cghair_format.cards.inverse import STRIP_TOLERANCE, fit_strip, solve_uvd
from cghair_format.cards.normals import orthonormalize
from cghair_format.geometry import strand_points


def _curved_cards(c=3, m=10, seed=0):
    """Cards along bent, twisting spines with varying widths."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, m + 1)
    spine = np.stack([np.sin(2 * t)[None] + rng.uniform(-1, 1, (c, 1)),
                      -3 * t[None] + rng.uniform(-1, 1, (c, 1)),
                      0.5 * t[None] ** 2 * rng.uniform(-1, 1, (c, 1))], -1)
    twist = t[None] * rng.uniform(0, 1.2, (c, 1))
    normal = orthonormalize(np.stack([np.cos(twist), 0.1 * np.ones_like(twist), np.sin(twist)], -1), spine)
    half = rng.uniform(0.05, 0.2, (c, m + 1))
    return Cards(spine.astype(np.float32), normal.astype(np.float32), half.astype(np.float32),
                 np.zeros(c, np.int32))


def _decode(cards, card, uvd):
    return strand_points(cards, card, uvd[:, None, :].astype(np.float32))[:, 0].astype(np.float64)


def test_exact_solution_for_points_near_the_card():
    cards = _curved_cards()
    rng = np.random.default_rng(1)
    n = 5000
    card = rng.integers(0, cards.count, n)
    uvd = np.stack([rng.uniform(0, 1, n), rng.uniform(0, 1, n), rng.uniform(-0.1, 0.1, n)], -1)
    x = _decode(cards, card, uvd)
    s = project_to_spines(cards.spine, card, x)
    got, solved = solve_uvd(cards, x, card, s)
    assert solved.all()
    err = np.linalg.norm(_decode(cards, card, got) - x, axis=-1)
    assert err.max() < 1e-5  # float32 decode of coordinates of order 1
    # the solution is the one nearest the card: |delta| never exceeds the generating one (+ rounding)
    assert (np.abs(got[:, 2]) <= np.abs(uvd[:, 2]) + 1e-5).all()


def test_points_off_the_strip_widen_and_extend_the_card():
    cards = _curved_cards(c=1, seed=2)
    rng = np.random.default_rng(3)
    n = 400
    card = np.zeros(n, np.int64)
    uvd = np.stack([rng.uniform(-0.08, 1.1, n), rng.uniform(-0.8, 1.8, n), rng.uniform(-0.05, 0.05, n)], -1)
    x = _decode(cards, card, uvd)
    s = project_to_spines(cards.spine, card, x)
    new, got, solved, rounds = fit_strip(cards, x, card, s)
    assert solved.all() and rounds >= 1
    assert (new.half_width >= cards.half_width).all() and (new.half_width > cards.half_width).any()
    assert got[:, 1].min() >= -STRIP_TOLERANCE and got[:, 1].max() <= 1 + STRIP_TOLERANCE
    assert got[:, 0].min() >= -STRIP_TOLERANCE and got[:, 0].max() <= 1 + STRIP_TOLERANCE
    err = np.linalg.norm(_decode(new, card, got) - x, axis=-1)
    assert err.max() < 1e-5


def test_points_inside_need_no_adjustment():
    cards = _curved_cards(c=2, seed=4)
    rng = np.random.default_rng(5)
    card = rng.integers(0, 2, 300)
    uvd = np.stack([rng.uniform(0.01, 0.99, 300), rng.uniform(0.05, 0.95, 300), rng.uniform(-0.02, 0.02, 300)], -1)
    x = _decode(cards, card, uvd)
    new, _, _, rounds = fit_strip(cards, x, card, project_to_spines(cards.spine, card, x))
    assert rounds == 0
    np.testing.assert_array_equal(new.half_width, cards.half_width)
