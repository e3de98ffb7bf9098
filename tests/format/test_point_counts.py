"""Strands of their own point counts (spec 3, PCNT): round trips lossless and quantized within the bound
on each strand's own points, Gaussians of the real segments only, and PCNT refused where it is wrong."""

import dataclasses

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format import container
from cghair_format.errors import AssetError, InvalidContentError, LimitError
from cghair_format.examples import example_asset, with_point_counts
from cghair_format.geometry import strand_points
from cghair_format.streams import StreamWriter


@pytest.fixture(scope="module")
def varied() -> cgh.HairAsset:
    asset = with_point_counts(example_asset(0, strands=48, points=12), seed=1)
    asset.source_color = np.random.default_rng(2).random(asset.uvd.shape).astype(np.float32)
    return asset


def own_points(asset: cgh.HairAsset) -> list[np.ndarray]:
    points = strand_points(asset.cards, asset.strand_card, asset.uvd)
    return [points[i, :n] for i, n in enumerate(asset.counts)]


def test_the_asset_counts_its_own_points_and_gaussians(varied):
    assert varied.variable and varied.counts.min() == 2 and varied.counts.max() == varied.points_per_strand
    assert varied.n_gaussians == int((varied.counts - 1).sum()) < varied.n_strands * (varied.points_per_strand - 1)
    order = np.arange(varied.n_strands)[::-1]
    assert np.array_equal(varied.take_strands(order).point_counts, varied.point_counts[order])
    for bad in (np.full(varied.n_strands, 1), np.full(varied.n_strands, 13), np.full(3, 4)):
        with pytest.raises(AssetError, match="point_counts"):
            dataclasses.replace(varied, point_counts=bad.astype(np.int32)).validate()


def test_lossless_keeps_every_strand_s_own_points_and_colours(varied):
    data, _ = cgh.encode(varied, "lossless")
    back = cgh.decode(data)
    assert cgh.read_info(data)["version"] == "2.1" and np.array_equal(back.point_counts, varied.point_counts)
    for mine, theirs in zip(own_points(varied), own_points(back), strict=True):
        assert np.array_equal(mine, theirs)
    strands = cgh.decode_strands(back)
    assert np.array_equal(strands.point_counts, varied.counts)
    assert np.array_equal(strands.points, np.concatenate(own_points(varied)))
    real = varied.real_points()
    assert np.abs(strands.colors - varied.source_color[real]).max() <= 0.5 / 255 + 1e-7


@pytest.mark.parametrize("profile", ["compact", "high"])
def test_quantized_points_lie_within_the_bound_of_each_strand_s_own(varied, profile):
    data, report = cgh.encode(varied, profile)
    back = cgh.decode(data)
    mine = report.in_file_order(varied)
    assert np.array_equal(back.counts, mine.counts)
    tol = cgh.PROFILES[profile].position_tolerance * report.bbox_diagonal
    errors = [np.linalg.norm(a - b, axis=-1).max() for a, b in zip(own_points(mine), own_points(back), strict=True)]
    assert max(errors) <= tol and max(errors) == pytest.approx(report.max_point_error, rel=1e-4)  # float32 differences
    real = mine.real_segments()
    assert np.abs(back.opacity[real] - mine.opacity[real]).max() <= cgh.PROFILES[profile].opacity_tolerance + 1e-7


def test_gaussians_are_the_real_segments_with_their_own_opacities_and_sh(varied):
    back = cgh.decode(cgh.encode(varied, "lossless")[0])
    g = cgh.decode_gaussians(back)
    assert g.count == back.n_gaussians
    points = own_points(back)
    means = np.concatenate([(x[1:] + x[:-1]) / 2 for x in points])
    np.testing.assert_allclose(g.means, means, rtol=0, atol=1e-6)
    assert np.array_equal(g.opacities, back.opacity[back.real_segments()])
    sh = cgh.gaussians.strand_sh(back)  # [S, P-1, NC, 3]: a strand of n points takes its first n - 1 sets
    assert np.array_equal(g.sh, sh[back.real_segments()])


def test_decode_points_refuses_a_variable_count_asset_and_names_decode_strands(varied):
    with pytest.raises(cgh.CghError, match="decode_strands"):
        cgh.decode_points(varied)
    same = example_asset(0)
    assert np.array_equal(cgh.decode_strands(same).points.reshape(same.uvd.shape), cgh.decode_points(same))


def test_equal_counts_write_no_pcnt_and_format_2_0(varied):
    full = dataclasses.replace(varied, point_counts=np.full(varied.n_strands, 12, np.int32))
    data, _ = cgh.encode(full, "compact")
    info = cgh.read_info(data)
    assert info["version"] == "2.0" and "PCNT" not in [c["type"] for c in info["chunks"]]
    assert cgh.decode(data).point_counts is None
    info = cgh.read_info(cgh.encode(varied, "compact")[0])
    pcnt = next(c for c in info["chunks"] if c["type"] == "PCNT")
    assert pcnt["required"] and info["gaussians"] == varied.n_gaussians
    assert info["point_counts"] == [2, 12]


def _with_pcnt(data: bytes, counts: np.ndarray | None) -> bytes:
    """``data`` with PCNT holding ``counts`` (None: without PCNT), checksums sealed again."""
    _, infos, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    chunks = [container.Chunk(i.type, payloads[i.type], i.required) for i in infos if i.type != "PCNT"]
    if counts is not None:
        w = StreamWriter()
        w.ints(counts)
        chunks.append(container.Chunk("PCNT", w.getvalue()))
    return container.pack(chunks)


@pytest.mark.parametrize("profile", ["lossless", "compact"])
def test_inconsistent_point_counts_are_refused_naming_pcnt(varied, profile):
    data, _ = cgh.encode(varied, profile)
    counts = cgh.decode(data).point_counts
    assert np.array_equal(cgh.decode(_with_pcnt(data, counts)).point_counts, counts)
    for bad, why in ((np.where(np.arange(len(counts)) == 3, 0, counts), "outside"),
                     (np.where(np.arange(len(counts)) == 3, 1, counts), "outside"),
                     (np.where(np.arange(len(counts)) == 3, 13, counts), "outside"),
                     (np.full(len(counts), 12), "no PCNT"),
                     (counts[:-1], "shape")):
        with pytest.raises(InvalidContentError, match=why) as caught:
            cgh.decode(_with_pcnt(data, bad))
        assert caught.value.chunk == "PCNT" and caught.value.offset is not None
    truncated = _with_pcnt(data, counts[:0])
    with pytest.raises((InvalidContentError, LimitError)) as caught:
        cgh.decode(truncated)
    assert caught.value.chunk == "PCNT"


def test_a_2_0_reader_refuses_pcnt_as_an_unknown_required_chunk(varied, monkeypatch):
    data, _ = cgh.encode(varied, "compact")
    known = set(cgh.codec.KNOWN_CHUNKS) - {"PCNT"}
    with pytest.raises(cgh.errors.UnknownRequiredChunkError, match="PCNT"):
        container.verify(data, known)


def test_free_placeholders_are_those_no_kept_sample_is_predicted_from():
    from cghair_format.strand_coder import Prediction, free_samples

    plan = Prediction(8, (2, 2, 2), 0, (4, 4, 4))
    free = free_samples(np.array([33, 5, 12, 2]), 33, plan).astype(bool)
    assert not free[0].any() and not free[:, :2].any()  # a strand of all its points; every kept sample
    assert not free[1, :5].any() and not free[2, :12].any()
    # 5 points: sample 3 interpolates 2, 4 and 6 (4 taps: 2 known samples either side), 6 takes 12, 12 takes
    # the base samples 8, 16 and 24 (and those their base predictions take); no kept sample reads the rest
    needed = {0, 1, 2, 3, 4, 6, 8, 12, 16, 24}
    assert set(np.flatnonzero(~free[1])) == needed
    assert free[3, 17:].all() and free[2, 25:32].all()


def test_free_placeholders_take_zero_residuals_and_cost_less():
    """The writer's dead zone lets free placeholders take zero (or the card neighbour's) residual: the
    file is smaller than with every placeholder coded to the strand's last point (strands of 24 points:
    12 leave few placeholders free), and the points keep the bound."""
    from cghair_format.codec import writer

    varied = with_point_counts(example_asset(0, strands=48, points=24), seed=1)

    with_free, report = cgh.encode(varied, "compact")
    zone = writer.DeadZone
    try:
        writer.DeadZone = lambda points, distance, counts=None: zone(points, distance)
        without, _ = cgh.encode(varied, "compact")
    finally:
        writer.DeadZone = zone
    assert len(with_free) < len(without)
    back = cgh.decode(with_free)
    mine = report.in_file_order(varied)
    errors = [np.linalg.norm(a - b, axis=-1).max() for a, b in zip(own_points(mine), own_points(back), strict=True)]
    assert max(errors) <= cgh.PROFILES["compact"].position_tolerance * report.bbox_diagonal


def test_info_refuses_a_pcnt_of_another_size_before_decompressing_it(varied):
    data, _ = cgh.encode(varied, "compact")
    _, infos, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    chunks = [container.Chunk(i.type, payloads[i.type] + (bytes(1 << 20) if i.type == "PCNT" else b""), i.required)
              for i in infos]
    with pytest.raises(LimitError, match="PCNT") as caught:
        cgh.read_info(container.pack(chunks))
    assert caught.value.chunk == "PCNT"


def test_lowered_opacities_count_the_real_gaussians(varied):
    """A file with PCNT records the lowered opacities of its real Gaussians (spec 4.4): placeholders'
    segments are never counted, and a count above the real Gaussians is refused naming the field."""
    import json

    from hostile import with_meta

    rng = np.random.default_rng(3)
    asset = dataclasses.replace(varied, opacity=rng.uniform(0, 1, varied.opacity.shape).astype(np.float32))
    data, report = cgh.encode(asset, "compact", negligible=np.ones(asset.opacity.shape, bool), opacity_budget=0.5)
    info = cgh.read_info(data)
    assert report.opacity.kept and report.opacity.marked == info["gaussians"] == asset.n_gaussians
    assert 0 < info["opacities"]["lowered"] == report.opacity.lowered <= info["gaussians"]

    def lowered(count):
        return lambda text: json.dumps((lambda m: m | {"quant": m["quant"] | {"opacity_lowered": count}})(
            json.loads(text)))

    with pytest.raises(InvalidContentError, match=r"'quant.opacity_lowered' is out of range: \d+ \(the file holds"):
        cgh.read_info(with_meta(data, lowered(info["gaussians"] + 1)))
