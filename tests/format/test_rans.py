"""The STRD entropy coder (spec 4.3.2): tokens, extra bits, multi-lane rANS and the context layout."""

import numpy as np
import pytest
import zstandard
from hypothesis import given, settings
from hypothesis import strategies as st

from cghair_format import rans, residual_coder
from cghair_format.errors import CghFormatError, InvalidContentError, TruncatedError
from cghair_format.quantize import zigzag
from cghair_format.streams import StreamReader, StreamWriter


@given(st.lists(st.integers(0, 2**64 - 1), min_size=1, max_size=60))
def test_tokens_and_extra_bits_are_exact(values):
    u = np.array(values, np.uint64)
    sym, extra = rans.tokens(u)
    width = rans.token_widths(sym)
    assert sym.max() < rans.ALPHABET
    assert width.tolist() == [int(v).bit_length() - 1 if v >= 16 else 0 for v in values]
    assert np.array_equal(rans.bit_length(u), [int(v).bit_length() for v in values])
    assert [int(t) if t < 16 else (1 << (int(t) - 12)) + int(e) for t, e in zip(sym, extra, strict=True)] == values
    assert len(rans.pack_bits(width, extra)) == (int(width.sum()) + 7) // 8


def test_extra_bits_are_packed_most_significant_first():
    """Spec 4.3.2: each value's bits below its leading one, MSB first, from each byte's top bit; the
    last byte padded with zeros."""
    packed = rans.pack_bits(np.array([3, 0, 5, 1, 64], np.uint8),
                            np.array([0b101, 7, 0b10011, 1, 2**63 + 1], np.uint64))
    bits = "101" + "10011" + "1" + "1" + "0" * 62 + "1"
    bits += "0" * (-len(bits) % 8)
    assert packed.tolist() == [int(bits[i:i + 8], 2) for i in range(0, len(bits), 8)]


def test_token_layout_matches_the_spec():
    sym, extra = rans.tokens(np.array([0, 15, 16, 31, 32, 2**63], np.uint64))
    assert sym.tolist() == [0, 15, 16, 16, 17, 75]
    assert rans.token_widths(sym).tolist() == [0, 0, 4, 4, 5, 63]
    assert extra.tolist() == [0, 0, 0, 15, 0, 0]
    assert rans.TOKEN_BITS[[0, 1, 2, 3, 8, 15, 16, 75]].tolist() == [0, 1, 2, 2, 4, 4, 5, 64]


def _round_trip(arrays, strand_card=None, classes=(1,)):
    strand_card = np.zeros(len(arrays[0]), np.int64) if strand_card is None else strand_card
    w = StreamWriter()
    chosen = residual_coder.write_residuals(w, arrays, strand_card, classes)
    r = StreamReader(w.getvalue(), "STRD")
    widths = [a.shape[1] for a in arrays]
    out = residual_coder.read_residuals(r, strand_card, widths, chosen)
    r.finish()
    return np.split(out, np.cumsum(widths)[:-1], axis=1), w.getvalue(), chosen


@settings(max_examples=40, deadline=None)
@given(strands=st.integers(1, 40), widths=st.lists(st.integers(1, 9), min_size=1, max_size=4),
       lanes=st.sampled_from([1, 3, 4096]), spread=st.sampled_from([1, 40, 2**20, 2**40]),
       cards=st.integers(1, 6), classes=st.sampled_from([1, 3, 8]), seed=st.integers(0, 10**6))
def test_residual_coder_round_trips(strands, widths, lanes, spread, cards, classes, seed):
    rng = np.random.default_rng(seed)
    arrays = [np.rint(rng.laplace(0, 1, (strands, n, 3)) * rng.integers(1, spread + 1)).astype(np.int64)
              for n in widths]
    strand_card = np.sort(rng.integers(0, cards, strands))
    original = residual_coder.LANES
    residual_coder.LANES = lanes  # several blocks and a partial last block
    try:
        out, _, chosen = _round_trip(arrays, strand_card, (classes,))
    finally:
        residual_coder.LANES = original
    assert chosen == classes
    for a, b in zip(arrays, out, strict=True):
        assert np.array_equal(a, b)


def test_the_card_neighbours_tokens_give_context_where_they_pay():
    """Spec 4.3.2: with neighbour classes, a token's table also depends on the bit class of the token one
    lane before, where that strand is on the same card. Where a card's strands have residuals alike in
    size sample by sample (which the strand's own previous sample does not tell) they code smaller so;
    where nothing links neighbours the larger tables cost more than they save, and the writer keeps one
    class."""
    rng = np.random.default_rng(3)
    strand_card = np.repeat(np.arange(200), 40)
    size = rng.choice([0, 6], (200, 12, 3))[strand_card]  # per card, sample and channel: zero or not
    alike = [np.rint(rng.laplace(0, 1, (8000, 12, 3)) * size).astype(np.int64)]
    sizes = {}
    for classes in ((1,), (3,), (3, 1)):
        out, data, chosen = _round_trip(alike, strand_card, classes)
        assert np.array_equal(out[0], alike[0])
        sizes[classes] = len(zstandard.compress(data, 19)), chosen  # as in a file: the tables are zstd-packed
    assert sizes[(3,)][0] < 0.95 * sizes[(1,)][0] and sizes[(3, 1)] == sizes[(3,)]
    unrelated = [np.rint(rng.laplace(0, 1, (300, 12, 3)) * 3).astype(np.int64)]
    assert _round_trip(unrelated, np.zeros(300, np.int64), (3, 1))[2] == 1


def test_residuals_beyond_float64_integers_are_refused():
    w = StreamWriter()
    residual_coder.write_residuals(w, [np.array([[[0, -2**52 - 1, 0]]], np.int64)])  # z = 2^53 + 1
    with pytest.raises(InvalidContentError, match="float64"):
        residual_coder.read_residuals(StreamReader(w.getvalue(), "STRD"), np.zeros(1), [1], 1)


def test_skewed_residuals_cost_less_than_a_bit_each():
    rng = np.random.default_rng(0)
    arrays = [(rng.random((3000, 30, 3)) < 0.05).astype(np.int64) * rng.choice([-1, 1], (3000, 30, 3))]
    _, data, _ = _round_trip(arrays)
    r = StreamReader(data, "STRD")
    r.array((96, rans.ALPHABET), "tables")
    r.array((None,), "states")
    coded = 2 * len(r.array((None,), "words")) + len(r.array((None,), "extra bits"))  # the symbols' bytes
    symbols = 3000 * 30 * 3
    entropy = symbols * (-(0.95 * np.log2(0.95) + 0.05 * np.log2(0.025))) / 8  # 0.34 bits a symbol
    assert coded < 1.05 * entropy < symbols / 8


def _coded(strands=50):
    rng = np.random.default_rng(1)
    arrays = [rng.integers(-300, 300, (strands, 4, 3)), rng.integers(-2, 3, (strands, 7, 3))]
    w = StreamWriter()
    residual_coder.write_residuals(w, arrays)
    return w.getvalue(), arrays


def _records(data):
    r = StreamReader(data, "STRD")
    tables = r.array((2 * 96, rans.ALPHABET), "t")
    states = r.array((None,), "s")  # ceil(50 / 8) lanes
    words = r.array((None,), "w")
    extra = r.array((None,), "e")
    return tables, states, words, extra


def _rebuild(tables, states, words, extra):
    w = StreamWriter()
    for a in (tables, states, words, extra):
        w.array(a)
    return w.getvalue()


@pytest.mark.parametrize("damage, error", [
    ("state_low", InvalidContentError), ("words_short", TruncatedError), ("words_long", InvalidContentError),
    ("state_changed", CghFormatError), ("extra_short", InvalidContentError), ("table_code", InvalidContentError),
    ("table_two_rests", InvalidContentError), ("table_no_rest", InvalidContentError),
    ("table_overfull", InvalidContentError), ("table_emptied", InvalidContentError),
])
def test_damaged_streams_are_refused(damage, error):
    data, _ = _coded()
    tables, states, words, extra = (a.copy() for a in _records(data))
    if damage == "state_low":
        states[3] = 5
    elif damage == "words_short":
        words = words[:-40]
    elif damage == "words_long":
        words = np.r_[words, np.uint16(7)]
    elif damage == "state_changed":
        states[0] ^= 1 << 20
    elif damage == "extra_short":
        extra = extra[:-1]
    elif damage == "table_emptied":  # a table the stream codes with, left empty (as an unused one is)
        tables[np.flatnonzero(tables.any(axis=1))[0]] = 0
    else:  # the tables: a code beyond 49, a second or no remainder entry, entries that leave it below 1
        row = tables[np.flatnonzero(tables.any(axis=1))[0]]
        rest = int(np.flatnonzero(row == rans.REST)[0])
        if damage == "table_code":
            row[(rest + 1) % rans.ALPHABET] = 50
        elif damage == "table_two_rests":
            row[(rest + 1) % rans.ALPHABET] = rans.REST
        elif damage == "table_no_rest":
            row[rest] = 1
        else:
            row[(rest + 1) % rans.ALPHABET] = rans.MAX_CODE
    with pytest.raises(error) as info:
        residual_coder.read_residuals(StreamReader(_rebuild(tables, states, words, extra), "STRD"), np.zeros(50),
                                      [4, 7], 1)
    assert isinstance(info.value, CghFormatError) and "STRD" in str(info.value)
    if damage == "table_emptied":
        assert "empty frequency table" in str(info.value)


def test_a_stream_claiming_more_symbols_than_it_can_hold_is_refused_at_once():
    """Every symbol costs at least log2(4096 / 4080) bits, so a short stream cannot stand for an
    enormous asset: the decoder refuses before looping over it."""
    import time

    w = StreamWriter()
    residual_coder.write_residuals(w, [np.zeros((8 * 4096, 1, 3), np.int64)])
    codes = StreamReader(w.getvalue(), "STRD").array((96, rans.ALPHABET), "t")
    assert rans.table_frequencies(codes, "t").max() == rans.MAX_FREQ
    start = time.perf_counter()
    with pytest.raises(InvalidContentError, match="cannot fit"):
        residual_coder.read_residuals(StreamReader(w.getvalue(), "STRD"), np.zeros(8 * 4096), [4000], 1)
    assert time.perf_counter() - start < 1


def test_tables_with_a_free_symbol_are_refused():
    freq = np.zeros((1, rans.ALPHABET), np.int64)
    freq[0, 0] = rans.TOTAL
    with pytest.raises(InvalidContentError, match="above"):
        rans.Tables(freq, "STRD")
    # the writer gives a table of one token another, enough to keep that one within MAX_FREQ
    codes, freq = rans.quantize_tables(np.eye(1, rans.ALPHABET, 0, dtype=np.int64) * 1000)
    assert freq[0, 0] == rans.MAX_FREQ and freq.sum() == rans.TOTAL and (codes > 0).sum() == 2


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 10**6), tokens=st.integers(1, rans.ALPHABET), skew=st.floats(0.0, 8.0))
def test_the_writers_tables_decode_to_what_it_codes_with(seed, tokens, skew):
    """Any counts, flat or dominated by one token: the stored codes decode to the frequencies the writer
    codes with, which sum to TOTAL and give every counted token at least 1 and none above MAX_FREQ."""
    rng = np.random.default_rng(seed)
    counts = np.zeros((2, rans.ALPHABET), np.int64)  # the second row: a table never used
    picked = rng.choice(rans.ALPHABET, tokens, replace=False)
    counts[0, picked] = np.maximum(1, rng.exponential(1.0, tokens) ** skew * 1000).astype(np.int64)
    codes, freq = rans.quantize_tables(counts)
    assert codes.dtype == np.uint8 and not codes[1].any() and not freq[1].any()
    assert np.array_equal(rans.table_frequencies(codes, "t"), freq)
    row = freq[0]
    assert row.sum() == rans.TOTAL and row.max() <= rans.MAX_FREQ and ((row > 0) >= (counts[0] > 0)).all()
    rans.Tables(freq, "t")


def test_the_estimate_counts_what_the_tokens_cost():
    """The writer's yardstick, counted without forming tokens, equals the order-0 cost of the tokens
    the coder would form from the zigzag-coded residuals."""
    rng = np.random.default_rng(0)
    r = np.concatenate([rng.laplace(0, 3, 5000), rng.laplace(0, 400, 500), [-9, -8, 7, 8, 2**40, -2**40]])
    r = np.rint(r).astype(np.int64)
    sym, _ = rans.tokens(zigzag(r))
    counts = np.bincount(sym, minlength=rans.ALPHABET)
    used = counts > 0
    extra = counts @ rans.TOKEN_WIDTHS.astype(np.int64)
    expected = (-(counts[used] * np.log2(counts[used] / r.size)).sum() + extra) / 8
    assert rans.estimate_bytes(r) == pytest.approx(expected, rel=1e-12)
    assert rans.estimate_bytes(np.zeros(10, np.int64)) == 0


def test_a_strand_with_no_card_neighbour_before_it_has_a_neighbour_class_of_its_own():
    """Spec 4.3.2: with K > 1 neighbour classes, e = 1 + min(b, K - 2) after a card neighbour whose token
    has bit class b, and 0 for the first strand of a card or block, not the class of a neighbour's 0."""
    args = (np.int32(0), np.int32(0), np.zeros(4, np.uint8), np.zeros(4, np.uint8))
    neighbour, after = np.array([0, 0, 3, 9], np.uint8), np.array([False, True, True, True])
    assert list(residual_coder._table(*args, neighbour, after, 5)) == [0, 1, 4, 4]
    assert list(residual_coder._table(*args, neighbour, after, 1)) == [0, 0, 0, 0]
