"""Built-in hairstyles: counts, determinism, no strand inside the head, colour variation."""

from __future__ import annotations

import numpy as np
import pytest

from cghair_format.errors import AssetError
from cghair_format.synth import HEAD_RADII, STYLES, inside_head, melanin_rgb, synthesize


@pytest.mark.parametrize("style", sorted(STYLES))
def test_style_shape(style):
    s = synthesize(style, 400, 32, seed=1)
    assert s.count == 400 and set(s.point_counts) == {32}
    assert (s.meters_per_unit, s.up_axis) == (1.0, "Y")
    a = s.to_array()
    assert not inside_head(s.points).any(), "a strand enters the head"
    for f in (0.25, 0.5, 0.75):  # nor do the segments between points cut through it
        assert not inside_head(a[:, :-1] * (1 - f) + a[:, 1:] * f).any()
    # roots sit on the scalp: just outside the head, in its upper/back part
    rel = np.linalg.norm(a[:, 0] / HEAD_RADII, axis=1)
    assert (rel < 1.05).all()
    assert np.median(a[:, 0, 1]) > 0
    length = np.linalg.norm(np.diff(a, axis=1), axis=-1).sum(1)
    assert np.median(length) > 0.8 * STYLES[style].length
    assert s.colors.shape == (400 * 32, 3) and 0 <= s.colors.min() and s.colors.max() <= 1
    assert s.widths.shape == (400 * 32,) and (s.widths > 0).all()


def test_curly_styles_curl_and_straight_does_not():
    def tortuosity(style):
        a = synthesize(style, 200, 64, seed=0).to_array()
        path = np.linalg.norm(np.diff(a, axis=1), axis=-1).sum(1)
        return float(np.median(path / np.linalg.norm(a[:, -1] - a[:, 0], axis=1)))

    assert tortuosity("coily") > tortuosity("curly") > 1.2 * tortuosity("straight")


def test_deterministic_and_seed_dependent():
    a = synthesize("wavy", 100, 16, seed=5)
    np.testing.assert_array_equal(a.points, synthesize("wavy", 100, 16, seed=5).points)
    assert not np.array_equal(a.points, synthesize("wavy", 100, 16, seed=6).points)


def test_colour_variation_per_strand_and_along_strands():
    plain = synthesize("long", 500, 32, seed=2)
    multi = synthesize("long", 500, 32, seed=2, multitone=True)
    pc = plain.colors.reshape(500, 32, 3)
    mc = multi.colors.reshape(500, 32, 3)
    assert pc[:, 0].std(0).max() > 0.005  # strands differ
    # multitone: tips are clearly lighter than roots
    assert (mc[:, -1].mean() - mc[:, 0].mean()) > 2 * (pc[:, -1].mean() - pc[:, 0].mean())
    assert (mc[:, -1].mean() - mc[:, 0].mean()) > 0.1


def test_melanin_darkens():
    rgb = melanin_rgb(np.array([0.2, 2.0, 8.0]), np.zeros(3))
    assert (np.diff(rgb.mean(1)) < 0).all()
    assert (rgb[:, 0] >= rgb[:, 2]).all()  # hair is warmer than grey: red reflects most


def test_bad_arguments():
    with pytest.raises(AssetError, match="unknown hairstyle"):
        synthesize("mohawk")
    with pytest.raises(AssetError, match="at least"):
        synthesize("short", 0, 10)


def test_full_size_head_stays_outside():
    import time

    t0 = time.perf_counter()
    s = synthesize("coily", 10_000, 64, seed=0)
    print(f"synthesize coily 10,000 x 64: {time.perf_counter() - t0:.2f} s")  # a figure, not asserted
    assert not inside_head(s.points).any()
