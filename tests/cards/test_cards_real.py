"""The card builder on the real hair models in ../shared/data/hair (skipped when absent).

The fast tests use the two 100-strand models; the slow test builds every model at its own size
with the default options (800 cards, 64 groups, 32 segments, 100 points) and prints a table.
"""

import time

import numpy as np
import pytest
from cards_helpers import MAX_TARGET, MEAN_TARGET, SMALL_REAL, STRIP_TOLERANCE, load_real
from hairdata import REAL_FILES

import cghair_format as cgh
from cghair_format.cards import build_cards
from cghair_format.geometry import spine_tangents


def _check(build):
    a = build.asset
    n = a.cards.normal.astype(np.float64)
    assert np.abs(np.linalg.norm(n, axis=-1) - 1).max() < 1e-5
    assert np.abs((n * spine_tangents(a.cards.spine.astype(np.float64))).sum(-1)).max() < 1e-3
    v = a.uvd[..., 1]
    # sane geometry, not only an exact decode: wild solutions (huge delta, far extrapolation) quantize badly
    diag = build.error.bbox_diagonal
    assert np.abs(a.uvd[..., 2]).max() <= 0.25 * diag and a.cards.half_width.max() <= 0.25 * diag
    assert a.uvd[..., 0].min() >= -STRIP_TOLERANCE and a.uvd[..., 0].max() <= 1 + STRIP_TOLERANCE
    assert v.min() >= -STRIP_TOLERANCE and v.max() <= 1 + STRIP_TOLERANCE
    assert build.error.mean_rel <= MEAN_TARGET, build.error.line("error")
    assert build.error.max_rel <= MAX_TARGET, build.error.line("error")


def _check_quantized(asset):
    """Both quantized profiles meet their point bound on the built cards (the writer codes the points on
    its coarsely quantized cards, spec 7)."""
    for profile in ("compact", "high"):
        data, report = cgh.encode(asset, profile)
        decoded = cgh.decode_strands(cgh.decode(data)).points.astype(np.float64)  # each strand's own points
        expected = cgh.decode_strands(report.in_file_order(asset)).points.astype(np.float64)
        bound = cgh.PROFILES[profile].position_tolerance * report.bbox_diagonal
        assert np.linalg.norm(decoded - expected, axis=-1).max() <= bound, (profile, report.max_point_error / bound)


@pytest.mark.parametrize("name", SMALL_REAL)
def test_small_real_models(name):
    strands = load_real(name)
    build = build_cards(strands, n_cards=10, n_groups=3, segments=16, points=50, progress=False)
    _check(build)
    _check_quantized(build.asset)


@pytest.mark.parametrize("name", SMALL_REAL)
def test_small_real_models_at_their_own_point_counts(name):
    """Bangs (5..21 points a strand) and Curly (10..47) keep every strand's own points; both quantized
    profiles meet their bound against those points."""
    strands = load_real(name)
    build = build_cards(strands, n_cards=10, n_groups=3, segments=16, progress=False)
    assert build.resampling is None and np.array_equal(build.asset.counts, strands.point_counts)
    assert build.asset.variable and build.error.max_rel <= MAX_TARGET
    for profile in ("compact", "high"):
        data, report = cgh.encode(build.asset, profile)
        after = build.error_of(cgh.decode(data), report)
        bound = cgh.PROFILES[profile].position_tolerance
        assert after.max_abs <= bound * report.bbox_diagonal, (profile, after.max_rel / bound)
        assert report.bbox_diagonal == pytest.approx(after.bbox_diagonal, rel=1e-6)  # the user's own points'


def test_real_colours_are_used():
    strands = load_real("Bangs_100_binary.ply")
    assert strands.colors is not None
    b = build_cards(strands, n_cards=10, n_groups=3, segments=8, points=20, progress=False)
    assert b.colors is not None and b.colors.shape == (100, 20, 3)
    from cghair_format.gaussians import SH_C0

    dc = b.asset.appearance.codebooks[..., :6] * SH_C0 + 0.5  # the stored root / tip colours
    assert np.abs(dc.mean() - strands.colors.mean()) < 0.1


@pytest.mark.slow
def test_every_real_model_at_its_own_size():
    rows = []
    for name in REAL_FILES:
        strands = load_real(name)
        start = time.perf_counter()
        build = build_cards(strands, progress=False)
        seconds = time.perf_counter() - start
        rows.append((name, build, seconds))
        _check(build)
        _check_quantized(build.asset)
    print("\nmodel                         strands  cards groups  mean rel   max rel    seconds")
    for name, b, sec in rows:
        print(f"{name:<29}{b.info['strands']:>8}{b.info['cards']:>7}{b.info['groups']:>7}  "
              f"{b.error.mean_rel:.2e}  {b.error.max_rel:.2e}  {sec:8.1f}")


@pytest.mark.slow
def test_densified_straight_hair_at_the_paper_scale():
    # regression: a hooked-root guide extended backwards over itself once gave a card 4,000 units wide
    # and deltas of 1e5 (exact in float, but the codec could not quantize them)
    from cghair_format.strands import densify, resample

    strands = densify(resample(load_real("straight.hair"), 100, method="bspline"), 25_000, seed=0)
    build = build_cards(strands, progress=False)
    _check(build)
    assert build.unsolved_points == 0
    print("\n" + build.timing_table() + build.error.line("error"))
