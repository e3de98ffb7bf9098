"""Strand-point coding (spec 4.3): neighbour prediction across the strands of a card (an exact integer
transform the writer applies where it codes smaller), the base predictor choice and the dead zone."""

import json
import unittest.mock
from pathlib import Path

import numpy as np
import pytest
from cghfile import quant_of
from hairdata import load_hair
from hypothesis import given, settings
from hypothesis import strategies as st

import cghair_format as cgh
from cghair_format import codec, container
from cghair_format.codec import choices, chunks, reader, writer
from cghair_format.errors import InvalidContentError
from cghair_format.geometry import card_scales
from cghair_format.strand_coder import canonical_order, neighbour_decode, neighbour_encode, neighbour_order


@settings(max_examples=60, deadline=None)
@given(strands=st.integers(1, 60), cards=st.integers(1, 6), seed=st.integers(0, 10**6))
def test_neighbour_transform_is_an_exact_inverse(strands, cards, seed):
    rng = np.random.default_rng(seed)
    strand_card = rng.integers(0, cards, strands)
    r = rng.integers(-2**40, 2**40, (strands, 7, 3))
    mask = rng.random((7, 3)) < 0.5
    order, starts = neighbour_order(strand_card)
    stored = np.where(mask, neighbour_encode(r, order, starts), r)
    neighbour_decode(stored, order, starts, mask)
    assert np.array_equal(stored, r)


def test_a_strands_neighbour_is_the_one_before_it_on_its_card():
    strand_card = np.array([1, 0, 1, 0, 1, 1])
    order, starts = neighbour_order(strand_card)
    assert order.tolist() == [1, 3, 0, 2, 4, 5]
    assert starts.tolist() == [True, False, True, False, False, False]
    d = neighbour_encode(np.arange(6) * 10, order, starts)
    assert d.tolist() == [0, 10, 20, 20, 20, 10]  # the firsts of each card (1 and 0) stay plain


def test_the_writers_order_chains_alike_strands_card_by_card():
    """Card by card, from the smallest root v, each next strand is the most alike one left: root and
    steps every 8th point."""
    from cghair_format.examples import example_asset

    asset = example_asset(3, strands=40, points=17, cards=3)
    order = canonical_order(asset.cards, asset.strand_card, asset.uvd)
    assert sorted(order.tolist()) == list(range(40))
    cards = asset.strand_card[order]
    assert np.all(np.diff(cards) >= 0)
    su, sv = card_scales(asset.cards, 0.0)
    world = asset.uvd[:, ::8].astype(np.float64) * np.stack([su, sv, np.ones_like(su)], -1)[asset.strand_card][:, None]
    shape = np.concatenate([world[:, :1], np.diff(world, axis=1)], axis=1)  # the root, then the steps
    for c in np.unique(cards):
        chain = order[cards == c]
        assert asset.uvd[chain[0], 0, 1] == asset.uvd[asset.strand_card == c, 0, 1].min()
        for k in range(1, len(chain)):
            left = chain[k:]
            dist = np.abs(shape[left] - shape[chain[k - 1]]).sum(axis=(1, 2))
            assert dist[0] == dist.min()


@pytest.mark.slow  # builds cards of a real model (5-8 s)
def test_the_writer_stores_strands_in_canonical_order_unless_asked_to_keep_it():
    from cghair_format.cards import build_cards

    asset = build_cards(load_hair("Ratboy_mohawk.tfx"), n_cards=60, n_groups=4, points=32, seed=0,
                        progress=False).asset
    asset.strand_ids = np.arange(asset.n_strands, dtype=np.uint32) + 1000
    data, report = cgh.encode(asset, "compact")
    assert np.array_equal(report.strand_order, canonical_order(asset.cards, asset.strand_card, asset.uvd))
    decoded = cgh.decode(data)
    assert np.all(np.diff(decoded.strand_card) >= 0)  # grouped by card
    assert np.array_equal(decoded.strand_ids, 1000 + report.strand_order)  # ids travel with their strands
    in_order = report.in_file_order(asset)
    assert np.linalg.norm(cgh.decode_points(decoded) - cgh.decode_points(in_order), axis=-1).max() \
        <= 2e-4 * report.bbox_diagonal

    kept, kept_report = cgh.encode(asset, "compact", keep_order=True)
    assert kept_report.strand_order is None
    assert np.array_equal(cgh.decode(kept).strand_card, asset.strand_card)
    assert np.linalg.norm(cgh.decode_points(cgh.decode(kept)) - cgh.decode_points(asset), axis=-1).max() \
        <= 2e-4 * kept_report.bbox_diagonal
    assert report.chunk_sizes["STRD"] < kept_report.chunk_sizes["STRD"]  # the ids' own chunk aside


@pytest.mark.slow  # builds cards of a real model (5-8 s)
def test_real_hair_stores_neighbour_differences_and_decodes_the_same_points():
    from cghair_format.cards import build_cards
    from cghair_format.residual_coder import read_residuals, write_residuals
    from cghair_format.strand_coder import level_widths
    from cghair_format.streams import StreamReader, StreamWriter

    asset = build_cards(load_hair("Ratboy_mohawk.tfx"), n_cards=60, n_groups=4, points=32, seed=0,
                        progress=False).asset
    data, report = cgh.encode(asset, "compact")
    quant = quant_of(data)
    assert any(quant["neighbour"]), quant["neighbour"]
    decoded = decoded_within_bound(data, report, asset)

    # the same residuals stored without the transform (every mask 0) reconstruct the same points, and
    # their STRD is larger
    _, infos = container.read_table(data)
    payloads = container.unpack(data, set(codec.KNOWN_CHUNKS))[2]
    r = StreamReader(payloads["STRD"], "STRD")
    strand_card = np.cumsum(r.ints((asset.n_strands,), "strand_card"))
    columns = level_widths(asset.points_per_strand, quant["base_stride"])
    residuals = read_residuals(r, strand_card, columns, quant["neighbour_classes"])
    reader.undo_neighbour_prediction(strand_card, residuals, columns, quant["neighbour"])
    w = StreamWriter()
    w.ints(np.diff(strand_card, prepend=0))
    write_residuals(w, np.split(residuals, np.cumsum(columns)[:-1], axis=1), strand_card,
                    (quant["neighbour_classes"],))
    meta = json.loads(payloads["META"])
    meta["quant"]["neighbour"] = [0] * len(columns)
    payloads["META"], payloads["STRD"] = json.dumps(meta).encode(), w.getvalue()
    plain = container.pack([container.Chunk(i.type, payloads[i.type], i.required) for i in infos])
    assert np.array_equal(cgh.decode_points(cgh.decode(plain)), decoded)
    sizes = {info.type: info.stored for info in container.read_table(data)[1]}
    plain_sizes = {info.type: info.stored for info in container.read_table(plain)[1]}
    assert sizes["STRD"] < plain_sizes["STRD"]


@pytest.mark.parametrize("masks", [[0], [8, 0, 0, 0, 0], [0, 0, 0, 0, -1], "7", None, [True, 0, 0, 0, 0]])
def test_bad_neighbour_masks_are_refused(masks):
    with pytest.raises(InvalidContentError, match="neighbour"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(neighbour=masks)))


@pytest.mark.parametrize("orders", [2, [1, 2], [1, 2, 3], [0, 1, 1], ["1", 1, 1], [True, 1, 1], None])
def test_bad_base_orders_are_refused(orders):
    with pytest.raises(InvalidContentError, match=r"'quant.base_order(\[\d\])?' is out of range"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(base_order=orders)))


@pytest.mark.parametrize("taps", [[4, 4, 4], [4, 4, 4, 4, 4], [4, 4, 4, 3], [4, 4, 4, 10], [4, 4, 4, True],
                                  ["4", 4, 4, 4], 4])
def test_bad_level_taps_are_refused(taps):
    with pytest.raises(InvalidContentError, match=r"'quant.level_taps(\[\d\])?' is out of range"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(level_taps=taps)))


@pytest.mark.parametrize("halvings", [-1, 9, 2.5, "4", True, None])
def test_bad_newton_halvings_are_refused(halvings):
    with pytest.raises(InvalidContentError, match="newton_halvings"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(newton_halvings=halvings)))


@pytest.mark.parametrize("stretch", [0.5, 0, 17, "1.5", True, None])
def test_bad_stretch_max_is_refused(stretch):
    with pytest.raises(InvalidContentError, match="stretch_max"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(stretch_max=stretch)))


@pytest.mark.parametrize("guide", [-1, 4, True, False, "1", None, 1.5])
def test_bad_base_guide_is_refused(guide):
    with pytest.raises(InvalidContentError, match="base_guide"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(base_guide=guide)))


@pytest.mark.parametrize("guide", [-1, 2, True, "1", None, 0.5])
def test_bad_level_guide_is_refused(guide):
    with pytest.raises(InvalidContentError, match="level_guide"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(level_guide=guide)))


def test_level_references_with_neighbour_differences_on_the_levels_are_refused():
    """With ``level_guide`` the levels are differences from their references' already (spec 4.3)."""
    def edit(quant):
        quant.update(level_guide=1, neighbour=[0] + [7] * (len(quant["neighbour"]) - 1))
    with pytest.raises(InvalidContentError, match="refinement levels' masks must be 0 with level_guide"):
        cgh.decode(_vector_with_quant(edit))


@pytest.mark.parametrize("classes", [0, 9, "3", True, None, 2.5])
def test_bad_neighbour_classes_are_refused(classes):
    with pytest.raises(InvalidContentError, match="neighbour_classes"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(neighbour_classes=classes)))


@pytest.fixture(scope="module")
def wavy_hair():
    """harolongo's real strands (wavy, 21 points a strand) on 120 cards, and their compact file."""
    from cghair_format.cards import build_cards
    from cghair_format.strands import resample

    strands = resample(load_hair("harolongo.data"), 100, method="bspline")
    asset = build_cards(strands, n_cards=120, n_groups=4, points=100, seed=0, progress=False).asset
    return asset, cgh.encode(asset, "compact")


@pytest.mark.slow  # harolongo on 120 cards: a 20 s fixture, then 5-8 s a test
def test_wavy_strands_choose_wide_interpolation_and_code_smaller(wavy_hair, monkeypatch):
    """Strands that wave with a period of a few tens of points are under-sampled at the middle levels
    for 4-point interpolation: the writer takes wider ones there, and the file is smaller for it."""
    asset, (data, _) = wavy_hair
    taps = quant_of(data)["level_taps"]
    assert max(taps) > 4, taps
    monkeypatch.setattr(choices, "choose_level_taps", lambda *_: (4,) * len(taps))
    fours, _ = cgh.encode(asset, "compact")
    assert len(data) < len(fours)


@pytest.mark.slow  # harolongo on 120 cards: a 20 s fixture, then 5-8 s a test
def test_searched_newton_steps_code_wavy_hair_smaller_within_the_bound(wavy_hair, monkeypatch):
    """A full Newton step can land where the card bends away (spec 4.3); halving it instead of giving
    up keeps the world-guided prediction. Measured: 504,200 bytes against 680,304 without halving."""
    asset, coded = wavy_hair
    monkeypatch.setattr(writer, "NEWTON_HALVINGS", 0)
    smaller_than_the_writer_now_and_within_bound(asset, coded, "newton_halvings", 4, 0, 0.9)


@pytest.mark.slow  # harolongo on 120 cards: a 20 s fixture, then 5-8 s a test
def test_stretched_residual_steps_code_wavy_hair_smaller_within_the_bound(wavy_hair, monkeypatch):
    """A card's u and v scales are its longest segment and widest point; where it is shorter or
    narrower, refinement steps stretched to the local scale (spec 4.3) cost fewer bits for the same
    bound. Measured: 504,200 bytes against 525,472 unstretched."""
    asset, coded = wavy_hair
    monkeypatch.setattr(writer, "STRETCH_MAX", 1.0)
    smaller_than_the_writer_now_and_within_bound(asset, coded, "stretch_max", 1.5, 1.0, 0.98)


@pytest.mark.slow  # harolongo on 120 cards: a 20 s fixture, then 5-8 s a test
def test_base_samples_guided_by_the_neighbours_steps_code_wavy_hair_smaller_within_the_bound(wavy_hair,
                                                                                              monkeypatch):
    """On a bending card the steps of strands side by side differ in card coordinates more than in world
    space: base samples predicted by world steps of strands before them on the card (spec 4.3) code
    smaller. Measured: 504,200 bytes against 564,648 unguided (both at base stride 8)."""
    asset, coded = wavy_hair
    unguided(monkeypatch)
    smaller_than_the_writer_now_and_within_bound(asset, coded, "base_guide", 3, 0, 0.97)


@pytest.mark.slow  # harolongo on 120 cards: a 20 s fixture, then 5-8 s a test
def test_base_samples_following_the_most_alike_earlier_strand_code_wavy_hair_smaller(wavy_hair, monkeypatch):
    """Along a wavy card the strand whose last steps were most like a strand's is often not its chain
    neighbour: taking the step from the most alike of the strands before it on the card (``base_guide``
    3, spec 4.3) codes harolongo's own strands smaller than the neighbour's step. Measured (level
    references off): 504,200 bytes against 514,736. The 66 strands a card holds on average also take
    the decoder's scratch of 33 strands round more than once."""
    asset, coded = wavy_hair
    choose = choices.choose_base_samples
    monkeypatch.setattr(choices, "choose_base_samples", lambda *args: (choose(*args)[0], 1))
    smaller_than_the_writer_now_and_within_bound(asset, coded, "base_guide", 3, 1, 0.985)


@pytest.mark.slow  # harolongo on 120 cards: a 20 s fixture, then 5-8 s a test
def test_level_references_code_wavy_hair_smaller_within_the_bound(wavy_hair, monkeypatch):
    """Each base segment's refinement residuals as differences from those of the strand before it on
    the card whose steps around that segment were most alike (``level_guide``, spec 4.3), rather than
    the card neighbour's, code harolongo's own strands smaller. Measured: 502,816 bytes against
    504,200."""
    asset, coded = wavy_hair
    monkeypatch.setattr(choices, "choose_level_guide", lambda *_: False)
    smaller_than_the_writer_now_and_within_bound(asset, coded, "level_guide", 1, 0, 0.999)


def test_straight_strands_of_unequal_lengths_take_the_scaled_guide(monkeypatch):
    """Strands with a fixed point count step further the longer they are: where strands run straight,
    the neighbour's step scaled as the two strands' previous steps compare (``base_guide`` 2, spec 4.3)
    predicts better. Measured: 57,536 bytes against 58,160 unscaled and 57,672 unguided (with 12-bit
    token tables and 3 neighbour classes, on 1,500 strands: 36,400 against 37,592 unscaled)."""
    from cghair_format.cards import build_cards
    from cghair_format.synth import synthesize

    asset = build_cards(synthesize("straight", 3000, 32, seed=3), n_cards=40, n_groups=4, segments=16, points=32,
                        seed=0, progress=False).asset
    coded = cgh.encode(asset, "compact")
    choose = choices.choose_base_samples
    monkeypatch.setattr(choices, "choose_base_samples", lambda *args: (choose(*args)[0], 1))
    smaller_than_the_writer_now_and_within_bound(asset, coded, "base_guide", 2, 1, 0.995)


def test_card_blocks_never_split_a_card():
    """Guided base samples read the neighbour's decoded ones, so the coder's parallel blocks hold whole
    cards (a card's strands decode in file order)."""
    from cghair_format.strand_coder import card_blocks, neighbour_order

    card = np.repeat(np.arange(7), [1, 3000, 5, 2047, 1, 4000, 2])
    _, starts = neighbour_order(card)
    blocks = card_blocks(starts, rows=2048)
    assert blocks[0].start == 0 and blocks[-1].stop == len(card)
    assert all(a.stop == b.start for a, b in zip(blocks[:-1], blocks[1:], strict=True))
    assert all(starts[b.start] for b in blocks) and len(blocks) > 1
    assert card_blocks(np.zeros(0, bool)) == []


@pytest.mark.parametrize(("seed", "kept"), [(4, False), (1, True)])
def test_a_mix_of_widths_the_estimate_prefers_is_kept_only_where_it_codes_smaller(seed, kept, monkeypatch):
    """The order-0 estimate prefers wider interpolation at some levels of these example assets; on the
    first the coded sample is larger (the contexts and the frequency tables disagree) and the writer
    keeps 4, on the second it is smaller and the writer keeps the mix. Either way the strand points
    code the smaller of the two (on the second by 2 bytes, which META's larger widths take back)."""
    from cghair_format.examples import example_asset

    coded, tried = [], []
    real_bytes, real_sample = choices.coded_bytes, choices.sample_residuals

    def bytes_spy(stored):
        coded.append(real_bytes(stored))
        return coded[-1]

    def sample_spy(cmap, strand_card, y, scale, plan, zone, *more):
        tried.append(plan.level_taps)
        return real_sample(cmap, strand_card, y, scale, plan, zone, *more)

    monkeypatch.setattr(choices, "coded_bytes", bytes_spy)
    monkeypatch.setattr(choices, "sample_residuals", sample_spy)
    data, report = cgh.encode(example_asset(seed), "compact")
    mixed, fours = coded[-4:-2]  # the level widths, then the level references (two codings), made once
    pick = next(taps for taps in tried if taps and len(set(taps)) > 1)  # after 2, 4 and 6 everywhere
    assert (mixed < fours) == kept
    assert quant_of(data)["level_taps"] == (list(pick) if kept else [4, 4, 4, 4])
    monkeypatch.setattr(choices, "choose_level_taps", lambda *_: (4, 4, 4, 4) if kept else pick)  # the other, forced
    assert cgh.encode(example_asset(seed), "compact")[1].chunk_sizes["STRD"] > report.chunk_sizes["STRD"]


def test_a_step_beyond_the_length_limit_is_refused():
    """A corrupt but well-formed step (1e40 scene units, which would scale the residuals past what float32
    holds) is refused from META, beyond MAX_LENGTH."""
    with pytest.raises(InvalidContentError, match="'quant.step' is out of range"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(step=1e40)))


def decoded_within_bound(data: bytes, report, asset) -> np.ndarray:
    """The points the compact file ``data`` decodes to, asserted within 2e-4 of the bounding-box diagonal
    of ``asset``'s (``report``: what the writer measured, and its strand order)."""
    decoded = cgh.decode_points(cgh.decode(data))
    expected = cgh.decode_points(report.in_file_order(asset))
    assert np.linalg.norm(decoded - expected, axis=-1).max() <= 2e-4 * report.bbox_diagonal
    return decoded


def smaller_than_the_writer_now_and_within_bound(asset, coded, key: str, ours, theirs, margin: float) -> None:
    """``coded`` (``(data, report)``, the writer's file of ``asset``) has META quant ``key`` = ``ours``;
    the writer as the test has since changed it writes ``theirs``, a file larger than ``coded`` by more
    than ``1 / margin``; both decode within the bound."""
    data, report = coded
    assert quant_of(data)[key] == ours
    other, other_report = cgh.encode(asset, "compact")
    assert quant_of(other)[key] == theirs
    assert len(data) < margin * len(other)
    for blob, rep in ((data, report), (other, other_report)):
        decoded_within_bound(blob, rep, asset)


def unguided(monkeypatch) -> None:
    """Make the writer keep its base stride but leave base samples unguided (spec 4.3)."""
    choose = choices.choose_base_samples
    monkeypatch.setattr(choices, "choose_base_samples", lambda *args: (choose(*args)[0], 0))


def _vector_with_quant(edit) -> bytes:
    """spec/vectors/small_compact.cgh with its META quant changed by ``edit`` (checksums redone)."""
    return _vector_with_meta(lambda meta: edit(meta["quant"]))


def _vector_with_meta(edit) -> bytes:
    """spec/vectors/small_compact.cgh with its META changed by ``edit`` (checksums redone)."""
    data = (Path(__file__).parents[2] / "spec" / "vectors" / "small_compact.cgh").read_bytes()
    _, infos = container.read_table(data)
    payloads = container.unpack(data, set(codec.KNOWN_CHUNKS))[2]
    meta = json.loads(payloads["META"])
    edit(meta)
    payloads["META"] = json.dumps(meta).encode()
    return container.pack([container.Chunk(i.type, payloads[i.type], i.required) for i in infos])


@pytest.mark.parametrize("edit", [
    lambda quant: quant.update(logit_step=quant.pop("logit_levels") / 16384),  # before the rANS strand coder
    lambda quant: [quant.pop(key) for key in ("level_taps", "newton_halvings")],  # before per-level widths
    lambda quant: quant.pop("newton_halvings"),  # before searched Newton steps
    lambda quant: quant.pop("stretch_max"),  # before stretched residual steps
    lambda quant: quant.pop("neighbour_classes"),  # before neighbour token contexts
    lambda quant: quant.pop("base_guide"),  # before guided base samples
    lambda quant: quant.update(half_bias=True) or quant.pop("weight_steps"),  # weights in rows, octahedral normals
    lambda quant: quant.pop("level_guide")])  # before level references
def test_a_pre_release_draft_file_gets_a_clear_error(edit):
    """Drafts of 1.0 stored ``logit_step``, or no ``level_taps``, ``newton_halvings``, ``stretch_max``,
    ``neighbour_classes``, ``base_guide``, ``weight_steps`` or ``level_guide``; say so, and what to do."""
    with pytest.raises(InvalidContentError, match="pre-release draft.*write the asset again"):
        cgh.decode(_vector_with_quant(edit))


@pytest.mark.parametrize("steps", [[], [0.1, 0.1], [0.1, 0.1, 0.0], [0.1, -0.1, 0.1], [0.1, 0.1, "0.1"],
                                   [0.1, 0.1, True], [0.1, 0.1, 0.1, 0.1], [0.1, 0.1, float("nan")]])
def test_weight_steps_out_of_range_are_refused(steps):
    # NaN is refused as META's JSON is read (no JSON number is NaN), before the field is checked
    with pytest.raises(InvalidContentError, match=r"'quant.weight_steps(\[\d\])?' is out of range|NaN is not a JSON"):
        cgh.decode(_vector_with_quant(lambda quant: quant.update(weight_steps=steps)))


def test_a_last_layer_that_does_not_output_the_sh_of_every_gaussian_is_refused():
    """Its rows are read as colour triples: a count the spec forbids never reaches that reading."""
    with pytest.raises(InvalidContentError, match="last layer must output"):
        cgh.decode(_vector_with_meta(lambda meta: meta["mlp"][-1].update(out=meta["mlp"][-1]["out"] + 1)))


@pytest.mark.parametrize(("chooser", "key", "choice"), [
    ("choose_base_order", "base_order", (1, 1, 1)), ("choose_base_order", "base_order", (2, 2, 2)),
    ("choose_base_order", "base_order", (2, 1, 1)), ("choose_base_order", "base_order", (1, 2, 1)),
    ("choose_level_taps", "level_taps", (2, 2, 2, 2)), ("choose_level_taps", "level_taps", (6, 6, 6, 6)),
    ("choose_level_taps", "level_taps", (8, 8, 8, 8)), ("choose_level_taps", "level_taps", (2, 6, 8, 4))])
def test_every_predictor_choice_decodes_within_the_bound(chooser, key, choice, monkeypatch):
    """The writer picks the base samples' predictor per channel and each level's interpolation width
    per file (spec 4.3); every choice decodes."""
    from cghair_format.examples import example_asset

    monkeypatch.setattr(choices, chooser, lambda *_: choice)
    asset = example_asset(5)
    data, report = cgh.encode(asset, "compact")
    assert quant_of(data)[key] == list(choice)
    decoded_within_bound(data, report, asset)


def test_parallel_strands_choose_the_previous_sample_as_base_predictor():
    """Strands that run side by side with the same steps but different bends code best as steps; a
    channel whose strands bend each their own way codes best extrapolated, channel by channel."""
    rng = np.random.default_rng(0)
    steps = np.cumsum(rng.normal(0, 30, (1, 64, 3)), axis=1)  # one shared wiggly path ...
    y = steps + rng.normal(0, 0.3, (200, 1, 3)) * 100  # ... offset per strand
    assert choices.choose_base_order(np.zeros(200, np.int64), y, 16) == (1, 1, 1)
    smooth = np.linspace(0, 1, 64)[None, :, None] ** 2 * rng.normal(0, 5000, (200, 1, 3))  # bends differ
    assert choices.choose_base_order(np.zeros(200, np.int64), smooth, 16) == (2, 2, 2)
    y[..., 0] = smooth[..., 0]
    assert choices.choose_base_order(np.zeros(200, np.int64), y, 16) == (2, 1, 1)


@pytest.mark.parametrize("neighbour", [True, False])
def test_the_dead_zone_stores_more_zeros_and_keeps_the_bound(neighbour, monkeypatch):
    """Where a cheaper residual still lands within 0.97 tol of the input, the writer takes it: the card
    neighbour's, whose stored difference is zero (when the writer chose to), else zero for a
    refinement sample (spec 4.3)."""
    from cghair_format import strand_coder
    from cghair_format.cards import build_cards

    asset = build_cards(load_hair("Ratboy_mohawk.tfx"), n_cards=60, n_groups=4, points=32, seed=0,
                        progress=False).asset
    calls = []
    real = strand_coder.encode_uvd

    def spy(*args, **kw):
        out = real(*args, **kw)
        if kw.get("dead_zone") is not None:
            calls.append((args, kw, out))
        return out

    monkeypatch.setattr(writer, "encode_uvd", spy)
    monkeypatch.setattr(choices, "encode_uvd", spy)
    monkeypatch.setattr(choices, "choose_neighbour_zone", lambda *_: neighbour)
    # base samples unguided: guided by the neighbour's steps (spec 4.3), they rarely find its residual
    # cheaper (Ratboy: 391 zeros with the neighbour zone, 392 without)
    unguided(monkeypatch)
    data, report = cgh.encode(asset, "compact")
    args, kw, (base, levels, world, *_) = calls[-1]
    assert kw["dead_zone"].neighbour == neighbour
    points, distance = kw["dead_zone"].points, kw["dead_zone"].distance
    assert distance == pytest.approx(0.97 * 2e-4 * report.bbox_diagonal)
    plain_base, plain_levels, *_ = real(*args)  # the same step without the dead zone
    strand_card = args[1]
    stored, _ = chunks.with_neighbour_prediction(strand_card, [base] + levels)
    plain_stored, _ = chunks.with_neighbour_prediction(strand_card, [plain_base] + plain_levels)
    zeros = sum(int((r == 0).sum()) for r in stored)
    assert zeros > 1.05 * sum(int((r == 0).sum()) for r in plain_stored)  # 1.10 with the neighbour zone
    # base samples get no plain zero, only the neighbour's residual: there the zeros are its doing (without
    # it, only the rare sample that rounding leaves beyond the tolerance moves, and may land on a zero)
    base_zeros, plain_base_zeros = int((stored[0] == 0).sum()), int((plain_stored[0] == 0).sum())
    if neighbour:
        assert base_zeros > plain_base_zeros
    else:
        assert abs(base_zeros - plain_base_zeros) <= 0.01 * plain_base_zeros
    assert np.linalg.norm(world - points, axis=-1).max() <= 2e-4 * report.bbox_diagonal
    decoded_within_bound(data, report, asset)


def test_the_dead_zone_moves_a_sample_that_rounding_leaves_beyond_the_tolerance(monkeypatch):
    """A step so coarse that rounding each channel leaves some points beyond the dead zone's distance:
    the writer takes the nearest of the 26 neighbouring residuals there instead (spec 4.3)."""
    from cghair_format import strand_coder
    from cghair_format.cards import build_cards

    asset = build_cards(load_hair("Ratboy_mohawk.tfx"), n_cards=60, n_groups=4, points=32, seed=0,
                        progress=False).asset
    calls = []
    real = strand_coder.encode_uvd

    def spy(*args, **kw):
        calls.append((args, kw))
        return real(*args, **kw)

    monkeypatch.setattr(writer, "encode_uvd", spy)
    monkeypatch.setattr(choices, "encode_uvd", spy)
    monkeypatch.setattr(writer, "STEP_START", 1.4)  # x tol: the first step tried
    cgh.encode(asset, "compact")
    args, kw = next(c for c in calls if c[1].get("dead_zone") is not None)
    zone = kw["dead_zone"]

    def beyond(world):
        return int((np.linalg.norm(world - zone.points, axis=-1) > zone.distance).sum())

    plain = beyond(real(*args)[2])  # every channel rounded, no dead zone
    assert plain > 100
    assert beyond(real(*args, **kw)[2]) < plain / 10


@pytest.mark.slow  # builds cards of a real model (5-8 s)
def test_the_writer_tries_the_neighbours_residual_where_a_cards_strands_are_alike():
    """Densified strands (each between two real ones) are much alike: the neighbour's residual pays.
    Ratboy's strands, evenly re-spaced, are not alike enough, and the writer keeps the plain dead zone."""
    from cghair_format.cards import build_cards
    from cghair_format.strands import densify, resample

    calls = []
    real = choices.choose_neighbour_zone

    def spy(*args, **kw):
        calls.append(real(*args, **kw))
        return calls[-1]

    with unittest.mock.patch.object(choices, "choose_neighbour_zone", spy):
        strands = resample(load_hair("Ratboy_mohawk.tfx"), 32)
        plain = build_cards(strands, n_cards=60, n_groups=4, points=32, seed=0, progress=False).asset
        cgh.encode(plain, "compact")
        plain_calls, calls[:] = list(calls), []
        dense = build_cards(densify(strands, 4 * strands.count, seed=0), n_cards=60, n_groups=4, points=32,
                            seed=0, progress=False).asset
        cgh.encode(dense, "compact")
    assert plain_calls and not any(plain_calls)  # once per step the writer tries
    assert calls and all(calls)


@pytest.mark.parametrize("order", [(1, 1, 1), (2, 2, 2), (2, 1, 2)])
def test_the_writers_base_estimate_codes_what_the_compiled_coder_stores(order):
    """The writer picks the base predictor from numpy's base_residuals; the compiled recurrence must store
    exactly those base residuals (spec 4.3), or the choice would be made on other numbers."""
    from cghair_format.examples import example_asset
    from cghair_format.geometry import CardMap
    from cghair_format.quantize import level_plan
    from cghair_format.strand_coder import Prediction, base_residuals, encode_uvd

    asset = example_asset(2, strands=30, points=40, cards=3)
    scale = np.abs(np.random.default_rng(0).normal(100, 10, (30, 3)))
    y = asset.uvd.astype(np.float64) * scale[:, None, :]
    base_idx, _ = level_plan(40, 16)
    base, *_ = encode_uvd(CardMap(asset.cards), asset.strand_card, y, scale, Prediction(16, order, 2))
    assert np.array_equal(base, base_residuals(y, base_idx, order))
    assert not np.array_equal(base_residuals(y, base_idx, (1, 1, 1)), base_residuals(y, base_idx, (2, 2, 2)))


def test_the_compiled_kernels_refuse_card_indices_they_would_read_outside():
    from cghair_format import _decoder
    from cghair_format.examples import example_asset
    from cghair_format.geometry import CardMap

    asset = example_asset(2, strands=5, points=6, cards=2)
    cmap = CardMap(asset.cards)
    with pytest.raises(ValueError, match="card index 2 outside"):
        cmap(np.array([2]), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="mismatched"):
        _decoder.map_points(cmap.frames, asset.cards.segments, np.zeros(2, np.int64), np.zeros((1, 3)),
                           np.zeros((2, 3)))


def test_the_compiled_recurrence_refuses_plans_and_layouts_it_would_read_outside():
    """The kernels read the plan's and the layout's arrays unchecked: their boundary checks them once."""
    from cghair_format import _decoder
    from cghair_format.examples import example_asset
    from cghair_format.geometry import CardMap
    from cghair_format.strand_coder import Layout, Prediction, level_widths, recurrence

    asset = example_asset(2, strands=5, points=12, cards=2)
    cmap = CardMap(asset.cards)
    plan = recurrence(12, Prediction(4, (2, 2, 2), 2, level_guide=True))
    layout = Layout(cmap.frames, cmap.segments, asset.strand_card.astype(np.int64), np.ones((5, 3)))
    res = np.zeros((5, sum(level_widths(12, 4)), 3), np.int64)

    def decode(plan=plan, layout=layout):
        scratch = [np.empty((_decoder.SCRATCH_STRANDS, 12, 3)) for _ in range(2)]
        return _decoder.decode_strands(plan, layout, np.arange(5), res, np.empty((5, 12, 3)), *scratch)

    assert decode() == 0 and len(plan.row_seg) > 0
    for match, bad in (("base segment is out of range", plan._replace(row_seg=plan.row_seg + 5)),
                       ("stretch_max", plan._replace(stretch_max=0.5)),
                       ("mismatched", plan._replace(base_order=np.ones(2, np.int64))),
                       ("interpolation width", plan._replace(level_taps=plan.level_taps + 9))):
        with pytest.raises(ValueError, match=match):
            decode(plan=bad)
    with pytest.raises(ValueError, match="card index 2 outside"):
        decode(layout=layout._replace(strand_card=layout.strand_card + 2))
