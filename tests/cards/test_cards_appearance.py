import numpy as np

from cghair_format.cards.appearance import (
    CODEBOOK_SIZE,
    LATENT_DIM,
    colour_profiles,
    default_appearance,
    default_opacity,
    default_thickness,
)
from cghair_format.gaussians import eval_sh, run_mlp, strand_latents


def _rgb(appearance, group, points):
    sh = run_mlp(appearance, strand_latents(appearance, group))
    sh = sh.reshape(len(group) * (points - 1), appearance.sh_coeffs, 3)
    dirs = np.tile([0.0, 0.0, 1.0], (len(sh), 1))
    return eval_sh(sh, dirs).reshape(len(group), points - 1, 3)


def test_input_colours_render_root_to_tip():
    s, p = 12, 20
    root = np.array([[0.9, 0.1, 0.1], [0.1, 0.8, 0.2], [0.2, 0.2, 0.9]])[np.arange(s) % 3]
    tip = root[::-1]
    t = np.linspace(0, 1, p)[None, :, None]
    colors = root[:, None] * (1 - t) + tip[:, None] * t
    group = (np.arange(s) >= 6).astype(np.int64)
    app = default_appearance(colour_profiles(colors, s), group, 2, p, sh_degree=3)
    assert app.codebooks.shape == (2, CODEBOOK_SIZE, LATENT_DIM) and app.weight_mode == "hard"
    rgb = _rgb(app, group, p)
    seg_t = (np.arange(p - 1) + 0.5) / (p - 1)
    root_prof = colour_profiles(colors, s)[:, 0]
    tip_prof = colour_profiles(colors, s)[:, 1]
    want = root_prof[:, None] * (1 - seg_t[None, :, None]) + tip_prof[:, None] * seg_t[None, :, None]
    # <= K distinct profiles per group: exact up to the 1e-4 rounding used to find distinct profiles
    np.testing.assert_allclose(rgb, want, atol=1e-4)
    assert np.abs(rgb[0, 0] - [0.9, 0.1, 0.1]).max() < 0.15


def test_no_colours_give_a_varied_brown():
    s, p = 200, 10
    prof = colour_profiles(None, s, seed=0)
    app = default_appearance(prof, np.zeros(s, np.int64), 1, p, sh_degree=1)
    rgb = _rgb(app, np.zeros(s, np.int64), p)
    mean = rgb.reshape(-1, 3).mean(0)
    assert mean[0] > mean[1] > mean[2] and 0.08 < mean.mean() < 0.5  # brown: red > green > blue, mid-dark
    assert rgb[:, 0].std(0).max() > 0.005  # strands differ
    assert (rgb[:, -1].mean(0) > rgb[:, 0].mean(0)).all()  # lighter tips


def test_opacity_and_thickness():
    o = default_opacity(3, 101)
    assert o.shape == (3, 100) and o[:, :90].min() == 1 and 0.5 < o[:, -1].max() < 1
    pts = np.zeros((4, 5, 3))
    pts[:, :, 0] = np.arange(4)[:, None] * 0.3  # neighbouring strands 0.3 apart
    pts[:, :, 1] = np.arange(5)[None]
    assert abs(default_thickness(pts, None) - 0.1) < 1e-9
    assert default_thickness(pts, np.full(20, 0.02)) == 0.01
