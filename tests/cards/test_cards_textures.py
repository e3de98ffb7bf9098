import numpy as np

from cghair_format.cards.textures import card_groups, strand_textures, texture_features, uv_splines


def test_uv_splines_keep_straight_lines():
    p = 30
    u = np.linspace(0, 1, p)
    uv = np.stack([u, 0.2 + 0.5 * u], -1)[None]
    dense = uv_splines(uv, 120)
    np.testing.assert_allclose(dense[0, :, 1], 0.2 + 0.5 * dense[0, :, 0], atol=1e-9)
    np.testing.assert_allclose(dense[0, [0, -1]], uv[0, [0, -1]], atol=1e-9)


def test_a_straight_strand_covers_one_column():
    p, size = 40, 32
    uv = np.stack([np.linspace(0, 1, p), np.full(p, 0.5)], -1)[None]
    tex = strand_textures(uv, np.array([0]), 1, size)[0]
    column = tex[:, 15:17].sum(1)  # v = 0.5 falls between texel columns 15 and 16
    assert np.abs(column[1:-1] - 1).max() < 0.05  # ~1 per row: anti-aliased across the two columns
    assert tex[:, :14].max() == 0 and tex[:, 18:].max() == 0
    assert 0 < tex[5, 15] < 1  # split between neighbours, not aliased into one


def test_placeholders_add_no_coverage():
    """A strand of 20 points padded to 40 with its last point covers what the strand alone covers."""
    u = np.linspace(0, 0.5, 20)
    own = np.stack([u, 0.3 + 0.2 * u], -1)
    padded = np.concatenate([own, np.repeat(own[-1:], 20, 0)])
    full = np.stack([np.linspace(0, 1, 40), np.full(40, 0.8)], -1)  # another strand, of all 40 points
    tex = strand_textures(np.stack([padded, full]), np.array([0, 1]), 2, 32, counts=np.array([20, 40]))
    np.testing.assert_allclose(tex[0], strand_textures(own[None], np.array([0]), 1, 32)[0], atol=1e-6)
    np.testing.assert_array_equal(tex[1], strand_textures(full[None], np.array([0]), 1, 32)[0])
    # without the counts, the repeated tip point piles its samples into the tip's texels
    blind = strand_textures(padded[None], np.array([0]), 1, 32)[0]
    assert blind[14:18].sum() > tex[0][14:18].sum() + 1


def test_groups_follow_texture_content():
    p = 30
    u = np.linspace(0, 1, p)
    left = np.stack([u, np.full(p, 0.2)], -1)
    right = np.stack([u, np.full(p, 0.8)], -1)
    uv = np.stack([left, left, right, right, left, right])
    card = np.arange(6)
    tex = strand_textures(uv, card, 6)
    assert texture_features(tex).shape == (6, 256)
    groups = card_groups(tex, 2, seed=0)
    assert groups[0] == groups[1] == groups[4] != groups[2] == groups[3] == groups[5]
    np.testing.assert_array_equal(groups, card_groups(tex, 2, seed=0))
    assert (card_groups(tex, 50) < 6).all()  # capped at the card count
