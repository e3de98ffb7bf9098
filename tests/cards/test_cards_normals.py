import numpy as np
import pytest
from cards_helpers import load_real, sheet, synth

from cghair_format.cards._util import project_to_spines
from cghair_format.cards.build import resample
from cghair_format.cards.cluster import cluster_strands
from cghair_format.cards.guide import guide_spines
from cghair_format.cards.normals import card_half_widths, card_normals, consistent_signs
from cghair_format.geometry import spine_tangents


def _normals_of(pts, n_cards, segments=10):
    labels = cluster_strands(pts, n_cards, seed=0)
    c = int(labels.max()) + 1
    spine, _ = guide_spines(pts, labels, c, segments)
    card = np.repeat(labels, pts.shape[1])
    flat = pts.reshape(-1, 3)
    s = project_to_spines(spine, card, flat)
    n = card_normals(spine, flat, card, s, hair_centre=pts[:, 0].mean(0))
    diag = float(np.linalg.norm(np.ptp(flat, axis=0)))
    return spine, n, card_half_widths(spine, n, flat, card, s, diag)


def _assert_orthonormal(spine, n):
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-9)
    assert np.abs((n * spine_tangents(spine)).sum(-1)).max() < 1e-6
    assert ((n[:, 1:] * n[:, :-1]).sum(-1) > 0).all()  # adjacent normals never point opposite ways


def test_sheet_normal_is_the_sheet_normal_and_width_its_half_extent():
    pts = sheet(40, 30, width=1.0)
    spine, n, w = _normals_of(pts, 1)
    _assert_orthonormal(spine, n)
    assert np.abs(n[0, :, 2]).min() > 0.999  # +-z
    assert np.abs(w[0] - 0.5).max() < 0.1  # half the sheet width, plus margin and the waviness


def test_l1_normal_ignores_a_stray_strand():
    pts = sheet(40, 30, width=1.0)
    pts[0, :, 2] += 0.8  # one strand far off the sheet
    spine, n, _ = _normals_of(pts, 1)
    assert np.abs(n[0, :, 2]).min() > 0.99


def test_normals_of_real_and_procedural_hair_are_unit_and_orthogonal():
    for strands in (synth("curly", 200, 30), load_real("Bangs_100.hair")):
        pts = resample(strands, 40)[0]
        spine, n, w = _normals_of(pts, 12)
        _assert_orthonormal(spine, n)
        assert (w > 0).all()


def test_consistent_signs_flips_opposite_neighbours():
    n = np.array([[[0, 0, 1.0], [0, 0, -1.0], [0, 0.1, -1.0], [0, 0, 1.0]]])
    out = consistent_signs(n)
    assert ((out[:, 1:] * out[:, :-1]).sum(-1) > 0).all()
    np.testing.assert_array_equal(out[0, 0], n[0, 0])


@pytest.mark.parametrize("segments", [1, 2])
def test_tiny_segment_counts(segments):
    spine, n, w = _normals_of(sheet(10, 8), 1, segments)
    assert n.shape == (1, segments + 1, 3)
    _assert_orthonormal(spine, n)
