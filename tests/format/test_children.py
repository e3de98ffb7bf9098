"""Interpolated strands (spec 4.5): strands stored as blends of two or three guide strands."""

import time

import numpy as np
import pytest
from cghfile import quant_of

import cghair_format as cgh
from cghair_format import children, codec, container
from cghair_format.codec import chunks, reader, writer
from cghair_format.errors import InvalidContentError
from cghair_format.examples import example_asset, with_interpolated_strands
from cghair_format.geometry import strand_points


@pytest.fixture(scope="module")
def groom():
    """64 guides and 64 strands blended from them, and their compact file."""
    asset = with_interpolated_strands(example_asset(0), seed=1)
    return asset, cgh.encode(asset, "compact")


def _points(asset):
    return strand_points(asset.cards, asset.strand_card, asset.uvd).astype(np.float64)


def test_blended_strands_are_stored_as_children_within_the_bound(groom):
    asset, (data, report) = groom
    children_count = quant_of(data).get("children", 0)
    assert children_count >= 32, children_count
    assert "CHLD" in report.chunk_sizes
    decoded = cgh.decode(data)
    err = np.linalg.norm(_points(decoded) - report.strands_in_file_order(_points(asset)), axis=-1)
    assert err.max() <= 2e-4 * report.bbox_diagonal
    assert err.max() == pytest.approx(report.max_point_error, rel=0, abs=1e-12)  # the writer measured the reader's
    without, _ = cgh.encode(asset, "compact", keep_order=True)  # keep_order stores no children
    assert "children" not in quant_of(without) and len(data) < len(without)


def test_children_come_last_and_take_their_parents_points(groom):
    asset, (data, report) = groom
    n = quant_of(data)["children"]
    payloads = container.unpack(data, set(codec.KNOWN_CHUNKS))[2]
    family = reader.read_family(payloads["CHLD"], asset.n_strands - n, n)
    assert (family.weights.sum(1) == children.WEIGHT_ONE).all()
    assert family.respaced.any() and not family.respaced.all()  # the example has both kinds
    points = _points(cgh.decode(data))
    guides = points[:family.guides]
    blended = children.blend(guides, family.parents, family.weights, family.respaced)
    # each child lies on its blend, up to where its card's map and the Newton search leave it
    assert np.linalg.norm(points[family.guides:] - blended, axis=-1).max() < 2e-6 * report.bbox_diagonal


def test_hair_without_blends_stores_no_children():
    data, report = cgh.encode(example_asset(0), "compact")
    assert "children" not in quant_of(data) and "CHLD" not in report.chunk_sizes


def test_the_search_finds_blends_of_nearby_strands():
    rng = np.random.default_rng(0)
    base = np.cumsum(rng.normal(0, 0.01, (40, 12, 3)), axis=1) + rng.uniform(0, 1, (40, 1, 3)) * [1, 0, 1]
    w = rng.dirichlet(np.ones(3), 20)
    near = np.argsort(np.linalg.norm(base[:, 0, None] - base[None, :, 0], axis=-1), axis=1)[:20, :3]
    kids = np.einsum("mk,mkpd->mpd", w, base[near])
    found = children.find_children(np.concatenate([base, kids]), tol=2e-3)  # 10-bit weights: 5e-4 per unit apart
    assert found.child[40:].sum() >= 18 and not found.child[found.parents[found.child].ravel()].any()
    assert (found.weights[found.child].sum(1) == children.WEIGHT_ONE).all()


def test_late_guides_decode_as_a_whole_coding_would(groom):
    """Children that the decoded guides place too far become guides, coded after the others: the
    writer codes only them, and gets what coding all the guides again gets."""
    asset, _ = groom
    points = _points(asset)
    diag = float(np.linalg.norm(points.reshape(-1, 3).max(0) - points.reshape(-1, 3).min(0)))
    prof, tol = cgh.PROFILES["compact"], 2e-4 * diag
    kids = children.find_children(points, tol)
    assert kids.child.sum() > 8
    arranged, at, order, family = writer._arrange(asset, points, kids)
    first = writer._quantize_geometry(arranged, prof, tol, diag, at, tol, None, family)
    late = np.zeros(len(points), bool)
    late[order[family.guides:][::3]] = True  # every third child, as if it had missed
    arranged, at, later, family = writer._arrange(asset, points, kids, late)
    step = writer._with_late_guides(first, order, later, family.guides, arranged, at)
    whole = writer._quantize_geometry(arranged, prof, tol, diag, at, tol, first.choices, family)
    for a, b in zip(step.residuals, whole.residuals, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(step.decoded_points, whole.decoded_points)
    np.testing.assert_array_equal(step.family.weights, whole.family.weights)


def _chld(data: bytes, edit) -> bytes:
    """``data`` with its CHLD family changed by ``edit`` (re-sealed)."""
    _, infos, payloads = container.unpack(data, set(codec.KNOWN_CHUNKS))
    n = quant_of(data)["children"]
    family = reader.read_family(payloads["CHLD"], cgh.read_info(data)["strands"] - n, n)
    payloads["CHLD"] = chunks.family_payload(edit(family))
    return container.pack([container.Chunk(i.type, payloads[i.type], i.required) for i in infos])


def _at(a: np.ndarray, index, value) -> np.ndarray:
    out = a.copy()
    out[index] = value
    return out


@pytest.mark.parametrize("edit, message", [
    (lambda f: f._replace(parents=f.parents + 10**6), "parent"),
    (lambda f: f._replace(parents=_at(f.parents, (0, 1), f.parents[0, 0] - 10**6)), "parent"),
    (lambda f: f._replace(weights=_at(f.weights, (0, 2), 9000)), "weight"),
    (lambda f: f._replace(respaced=_at(f.respaced.astype(np.uint8), 0, 2)), "flag"),
])
def test_a_bad_chld_is_refused(groom, edit, message):
    _, (data, _) = groom
    with pytest.raises(InvalidContentError, match=message):
        cgh.decode(_chld(data, edit))


def test_chld_and_the_children_count_go_together(groom):
    _, (data, _) = groom
    _, infos, payloads = container.unpack(data, set(codec.KNOWN_CHUNKS))
    chunks = [container.Chunk(i.type, payloads[i.type], i.required) for i in infos]
    with pytest.raises(InvalidContentError, match="CHLD"):
        cgh.decode(container.pack([c for c in chunks if c.type != "CHLD"]))
    meta = chunks[0].payload.replace(b'"children":', b'"childrem":')
    with pytest.raises(InvalidContentError, match="CHLD"):
        cgh.decode(container.pack([container.Chunk("META", meta)] + chunks[1:]))
    lossless = container.unpack(cgh.encode(example_asset(0), "lossless")[0], set(codec.KNOWN_CHUNKS))[2]
    with pytest.raises(InvalidContentError, match="CHLD"):  # lossless files have no children
        cgh.decode(container.pack([container.Chunk(t, lossless[t]) for t in codec.REQUIRED_CHUNKS]
                                  + [c for c in chunks if c.type == "CHLD"]))


@pytest.mark.filterwarnings("error")
def test_resealed_chld_garbage_is_refused_or_decodes(groom):
    """CHLD changed and re-sealed (valid checksums) reaches the children's decoder, which must answer
    with CghFormatError or a valid asset, within 1 s, without a warning."""
    _, (data, _) = groom
    _, infos, payloads = container.unpack(data, set(codec.KNOWN_CHUNKS))
    rng = np.random.default_rng(11)
    for _ in range(150):
        body = bytearray(payloads["CHLD"])
        for _ in range(int(rng.integers(1, 4))):
            body[int(rng.integers(0, len(body)))] = int(rng.integers(0, 256))
        bad = container.pack([container.Chunk(i.type, bytes(body) if i.type == "CHLD" else payloads[i.type],
                                              i.required) for i in infos], level=1)
        start = time.perf_counter()
        try:
            cgh.decode(bad).validate()
        except cgh.CghFormatError:
            pass
        assert time.perf_counter() - start < 1.0
