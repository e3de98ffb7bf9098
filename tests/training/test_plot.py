"""The ablation and sweep plots: our points as dots placed by size (log x) and PSNR, the paper's as squares;
the training curves as lines."""

from __future__ import annotations

import numpy as np
from PIL import Image

from training.ablation import PAPER_ABLATION, PAPER_SWEEPS
from training.plot import COLOURS, MARGIN, PALETTE, SIZE, plot_ablation, plot_curves, plot_sweep


def _dot_centre(img: np.ndarray, colour) -> np.ndarray:
    """Centre of the filled disc of ``colour`` in the plot area: the pixels whose 5 x 5 neighbourhood
    shares it (a 2-pixel square outline has none)."""
    same = np.all(img == np.asarray(colour, np.uint8), axis=-1)
    same[:, SIZE[0] - MARGIN[2]:] = False  # the legend
    h, w = same.shape
    inner = np.ones((h - 4, w - 4), bool)
    for dy in range(5):
        for dx in range(5):
            inner &= same[dy:dy + h - 4, dx:dx + w - 4]
    ys, xs = np.nonzero(inner)
    assert len(xs) > 20, f"no dot of colour {colour}"
    return np.array([xs.mean(), ys.mean()])


def test_dots_follow_size_and_psnr(tmp_path):
    rows = [{"variant": "unique", "psnr": 30.0, "appearance_bytes": 4e7},
            {"variant": "latents", "psnr": 29.0, "appearance_bytes": 4e5},
            {"variant": "single-sh", "psnr": 27.0, "appearance_bytes": 4e3}]
    path = plot_ablation(rows, PAPER_ABLATION, tmp_path / "a.png", "test")
    img = np.asarray(Image.open(path).convert("RGB"))
    assert img.shape == (SIZE[1], SIZE[0], 3)
    u, lat, single = (_dot_centre(img, COLOURS[v]) for v in ("unique", "latents", "single-sh"))
    # equal log steps in size give equal steps in x; PSNR up is y down
    assert abs((u[0] - lat[0]) - (lat[0] - single[0])) <= 1.5
    assert u[1] < lat[1] < single[1]
    assert abs((single[1] - lat[1]) - 2 * (lat[1] - u[1])) <= 1.5
    # 4e3 .. 1.637e8 bytes (the paper's unique) span the decades 10^3 .. 10^9
    per_decade = (SIZE[0] - MARGIN[2] - MARGIN[0]) / 6
    assert abs((u[0] - single[0]) - 4 * per_decade) <= 1.5


def test_sweep_dots_are_coloured_by_value(tmp_path):
    rows = [{"value": 30, "psnr": 29.0, "appearance_bytes": 1e6}, {"value": 10, "psnr": 30.0, "appearance_bytes": 1e5}]
    path = plot_sweep("K", rows, PAPER_SWEEPS["K"], tmp_path / "k.png", "K sweep")
    img = np.asarray(Image.open(path).convert("RGB"))
    # values in order (10, 30, then the paper's 60, 90) take the palette in order
    k10, k30 = _dot_centre(img, PALETTE[0]), _dot_centre(img, PALETTE[1])
    # 1e5 .. 4.72e6 bytes (the paper's K = 90) span the decades 10^4 .. 10^7
    per_decade = (SIZE[0] - MARGIN[2] - MARGIN[0]) / 3
    assert abs((k30[0] - k10[0]) - per_decade) <= 1.5 and k10[1] < k30[1]


def test_curves_are_lines_through_their_points(tmp_path):
    """A flat curve at 30 dB and one rising from 25 to 35 dB over 0..3,000 iterations: each colour lies on
    a straight line of its own, and the two cross at mid-plot (30 dB, 1,500 iterations)."""
    path = plot_curves({"unique": [(0, 30.0), (3000, 30.0)], "latents": [(0, 25.0), (3000, 35.0)]}, COLOURS,
                       tmp_path / "c.png", "curves")
    plot_area = np.asarray(Image.open(path).convert("RGB"))[:, :SIZE[0] - MARGIN[2]]
    fits = {}
    for variant in ("unique", "latents"):
        ys, xs = np.nonzero(np.all(plot_area == np.asarray(COLOURS[variant], np.uint8), axis=-1))
        assert len(xs) > 500, variant
        fits[variant] = np.polyfit(xs, ys, 1)  # pixel y against pixel x
        assert np.abs(np.polyval(fits[variant], xs) - ys).max() <= 3, variant
    assert abs(fits["unique"][0]) < 0.01 and fits["latents"][0] < -0.5  # flat; PSNR up is up in the image
    mid_x = (MARGIN[0] + SIZE[0] - MARGIN[2]) / 2
    assert abs(np.polyval(fits["unique"], mid_x) - np.polyval(fits["latents"], mid_x)) <= 2
