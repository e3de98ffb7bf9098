"""The reference decoder (cghair_format/reference_decoder.py, the spec's geometry in plain Python)
against the compiled one: the same card coordinates in float64 and the same float32 points, bit for
bit, on every vector; and a change of one rounding in the reference shows."""

from pathlib import Path

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format import codec, reference_decoder, strand_coder
from cghair_format.cli import main
from cghair_format.errors import UnsupportedVersionError
from cghair_format.geometry import strand_points, turn_cos_sin

VECTORS = Path(__file__).resolve().parents[2] / "spec" / "vectors"
QUANTIZED = sorted(p for p in VECTORS.glob("*.cgh")
                   if not p.name.startswith("reject_") and not cgh.read_info(p)["quant"]["lossless"])


def compiled(path: Path, monkeypatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The compiled decoder's guides' card coordinates in float64 (before spec 4.3's rounding to
    float32), and every strand's float32 ``uvd`` and points (a variable-count file's placeholders too)."""
    seen = {}

    def keep_float64(*args):
        seen["coordinates"] = strand_coder.decode_coordinates(*args)
        return seen["coordinates"].astype(np.float32)

    monkeypatch.setattr(codec.reader, "decode_uvd", keep_float64)
    asset = cgh.read(path)
    return seen["coordinates"], asset.uvd, strand_points(asset.cards, asset.strand_card, asset.uvd)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_every_quantized_vector_is_covered():
    assert len(QUANTIZED) >= 8
    assert any(cgh.read_info(p)["quant"].get("children") for p in QUANTIZED)
    assert {cgh.read_info(p)["quant"]["base_guide"] for p in QUANTIZED} >= {0, 3}
    assert any(cgh.read_info(p)["version"] == "2.1" for p in QUANTIZED)  # strands of their own point counts


@pytest.mark.parametrize("path", QUANTIZED, ids=lambda p: p.stem)
def test_both_decoders_give_every_vector_the_same_points_bit_for_bit(path, monkeypatch):
    coordinates, uvd, points = compiled(path, monkeypatch)
    ref = reference_decoder.decode_points(path.read_bytes())
    assert ref.index.tolist() == list(range(len(uvd)))
    guides = len(coordinates)
    assert same(ref.coordinates[:guides], coordinates)
    assert same(ref.uvd, uvd) and same(ref.points, points)
    assert ref.counts.tolist() == cgh.read(path).counts.tolist()


def test_one_rounding_changed_in_the_reference_shows(monkeypatch):
    """The comparison can fail: residual steps one ulp larger move the float64 coordinates."""
    path = VECTORS / "synth_curly_compact.cgh"
    coordinates = compiled(path, monkeypatch)[0]
    stretch = reference_decoder.stretch
    monkeypatch.setattr(reference_decoder, "stretch", lambda x, most: stretch(x * (1 + 2**-52), most))
    assert not same(reference_decoder.decode_points(path.read_bytes()).coordinates[:len(coordinates)],
                    coordinates)


def test_a_subset_of_cards_decodes_their_strands_alike(monkeypatch):
    path = VECTORS / "synth_children_compact.cgh"
    _, uvd, points = compiled(path, monkeypatch)
    ref = reference_decoder.decode_points(path.read_bytes(), {1})
    card = cgh.read(path).strand_card
    assert 0 < len(ref.index) < len(uvd) and set(card[ref.index].tolist()) == {1}
    assert same(ref.uvd, uvd[ref.index]) and same(ref.points, points[ref.index])


def test_turn_cosine_and_sine_are_the_same_bits_in_both_and_near_libm():
    near = np.linspace(-3, 3, 20_001)
    turns = np.concatenate([near, np.random.default_rng(0).uniform(-1e6, 1e6, 2000)])
    cos, sin = turn_cos_sin(turns)
    ref = np.array([reference_decoder.turn_cos_sin(float(t)) for t in turns])
    assert same(cos, ref[:, 0]) and same(sin, ref[:, 1])
    # libm's differ by its rounding of 2 pi t (up to 3 ulps of 6 pi here)
    assert np.abs(cos[:len(near)] - np.cos(2 * np.pi * near)).max() < 1e-14
    assert np.abs(sin[:len(near)] - np.sin(2 * np.pi * near)).max() < 1e-14
    quarters = turn_cos_sin(np.arange(-8, 9) / 4)
    assert set(np.concatenate(quarters).tolist()) == {-1.0, 0.0, 1.0}


def test_validate_reference_says_the_decoders_agree(capsys):
    path = VECTORS / "synth_children_compact.cgh"
    assert main(["validate", "--reference", str(path)]) == 0
    assert "the reference decoder gives the same points on all 96 strands, bit for bit" in capsys.readouterr().out
    assert main(["validate", "--reference", "--cards", "1", str(path)]) == 0
    assert main(["validate", "--reference", str(VECTORS / "minimal_lossless.cgh")]) == 0
    assert "nothing for the reference decoder" in capsys.readouterr().out


def test_validate_reference_fails_saying_how_many_strands_differ(capsys, monkeypatch):
    path = VECTORS / "synth_curly_compact.cgh"
    place = reference_decoder.place
    monkeypatch.setattr(reference_decoder, "place", lambda st, p0, goal, g, q: place(st, p0, goal, g, q | {
        "newton_steps": 0}))
    assert main(["validate", "--reference", str(path)]) == 1
    assert "the reference decoder gives other points on" in capsys.readouterr().out


def test_format_1_quantized_files_are_refused_saying_how_to_rewrite_them_lossless_ones_read():
    from cghair_format import container

    quantized = container.rewrite_header((VECTORS / "small_compact.cgh").read_bytes(), major=1)
    with pytest.raises(UnsupportedVersionError, match=r"rewrite it with cghair 0.1 .*cgh encode"):
        cgh.decode(quantized)
    lossless = (VECTORS / "minimal_lossless.cgh").read_bytes()
    assert same(cgh.decode(container.rewrite_header(lossless, major=1)).uvd, cgh.decode(lossless).uvd)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["straight.hair", "harolongo.data"])
def test_paper_scale_files_decode_alike_on_a_subset_of_cards(model, request, monkeypatch, tmp_path):
    """The benchmark's files (tests/bench/paper_scale.py: 25,000 strands of 100 points on 800 cards, real
    hair densified), compact: the strands of 48 evenly spaced cards and of the cards holding the parents
    of 8 children on those (a whole file takes the reference decoder 2 CPU minutes and 2.3 GB)."""
    from bench.paper_scale import paper_scale_asset

    from cghair_format import container

    asset = paper_scale_asset(model, request.config.cache.mkdir("cghair_paper_scale"))[0]
    path = tmp_path / "compact.cgh"
    cgh.write(asset, path, "compact")
    data = path.read_bytes()
    coordinates, uvd, points = compiled(path, monkeypatch)
    guides = len(coordinates)
    card = cgh.read(path).strand_card
    cards = reference_decoder.evenly_spaced_cards(asset.cards.count, 48)
    _, table = container.verify(data, set(codec.KNOWN_CHUNKS))
    chld = next(i for i in table if i.type == codec.FAMILY_CHUNK)
    family = codec.reader.read_family(container.payload(data, chld), guides, len(card) - guides)
    on_cards = [k for k in range(len(family.parents)) if card[guides + k] in cards][:8]
    cards |= {int(card[p]) for k in on_cards for p in family.parents[k]}
    ref = reference_decoder.decode_points(data, cards)
    is_guide = ref.index < guides
    print(f"{model}: {len(cards)} cards, {is_guide.sum()} guides, {(~is_guide).sum()} children compared")
    assert is_guide.sum() >= 200 and (~is_guide).sum() >= 8
    assert same(ref.coordinates[is_guide], coordinates[ref.index[is_guide]])
    assert same(ref.uvd, uvd[ref.index]) and same(ref.points, points[ref.index])


def test_both_decoders_give_every_animation_frame_the_same_cards(monkeypatch):
    """Spec 4.6: the reference decoder's frames, each from its block alone, against the compiled reader's,
    bit for bit; and a cosine 2^-20 off in the reference shows in the normals (the comparison can fail)."""
    from cghair_format.examples import example_animation, example_asset

    asset = example_asset(7, strands=16, points=6, cards=4, segments=6)
    data = cgh.encode(asset, "high", animation=example_animation(asset.cards, 36))[0]
    fast = cgh.read_animation(data)
    for f in range(fast.frames):
        cards = reference_decoder.decode_frame(data, f)
        assert same(np.array([c.spine for c in cards], np.float32), fast.spine[f])
        assert same(np.array([c.normal for c in cards], np.float32), fast.normal[f])
    cos_sin = reference_decoder.turn_cos_sin
    monkeypatch.setattr(reference_decoder, "turn_cos_sin", lambda a: (cos_sin(a)[0] * (1 + 2**-20), cos_sin(a)[1]))
    off = [np.array([c.normal for c in reference_decoder.decode_frame(data, f)], np.float32) for f in (3, 35)]
    assert not (same(off[0], fast.normal[3]) and same(off[1], fast.normal[35]))
