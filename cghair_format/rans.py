"""A multi-lane rANS entropy coder with static context tables (spec 4.3.2): tokens and tables in
numpy; the coding itself is compiled (:func:`._writer.encode_rans`, :func:`._decoder.decode_residuals`).

Unsigned integers are split into a token (coded with rANS under a frequency table that the caller
picks per symbol: its context) and raw extra bits. ``L`` lanes each hold a rANS state and code their
own symbols; all lanes share one stream of 16-bit words, so one step of the coder handles one
symbol of every lane with a few array operations.

Token of ``u``: ``u`` itself below ``DIRECT``; otherwise ``DIRECT + bitlen(u) - 5`` followed by the
``bitlen(u) - 1`` bits of ``u`` below its leading one (MSB first).
"""

from __future__ import annotations

import numpy as np

from . import _writer
from .errors import InvalidContentError
from .quantize import zigzag

DIRECT = 16
ALPHABET = DIRECT + 60  # bit lengths 5 .. 64
PROB_BITS = 12
TOTAL = 1 << PROB_BITS
LOW = 1 << 16  # states live in [LOW, 2^32); renormalization moves 16-bit words
MAX_FREQ = TOTAL - 16  # every symbol costs at least log2(TOTAL / MAX_FREQ) bits: no free symbols


def bit_length(u: np.ndarray) -> np.ndarray:
    """Bit length of unsigned integers (0 for 0), exact up to 2^64 - 1."""
    u = np.asarray(u, np.uint64)
    n = np.frexp(u.astype(np.float64))[1].astype(np.int64)  # exact below 2^53; above, rounding up ...
    high = n > 53
    if high.any():  # ... can add one: u < 2^(n-1) then
        n[high] -= (u[high] >> (n[high] - 1).astype(np.uint64)) == 0
    return n


# bit length of the smallest value of each token: what contexts are built from
TOKEN_BITS = np.r_[bit_length(np.arange(DIRECT)), np.arange(5, 65)].astype(np.uint8)
# the extra bits each token carries
TOKEN_WIDTHS = np.r_[np.zeros(DIRECT), np.arange(4, 64)].astype(np.uint8)


def tokens(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tokens and extra values of unsigned integers ``u`` (uint64); :func:`token_widths` gives each
    token's number of extra bits."""
    u = np.asarray(u, np.uint64)
    sym = u.astype(np.uint8)  # right below DIRECT; the others are set below
    extra = np.zeros(u.shape, np.uint64)
    big = np.flatnonzero(u.ravel() >= DIRECT)  # few: the work below is on them alone
    ub = u.ravel()[big]
    nb = bit_length(ub)
    sym.ravel()[big] = DIRECT + nb - 5
    extra.ravel()[big] = ub - (np.uint64(1) << (nb - 1).astype(np.uint64))
    return sym, extra


def token_widths(sym: np.ndarray) -> np.ndarray:
    return TOKEN_WIDTHS[sym]


def pack_bits(width: np.ndarray, value: np.ndarray) -> np.ndarray:
    """Concatenate each value's ``width`` low bits, MSB first, into bytes (zero padded; compiled)."""
    width = np.ascontiguousarray(width, np.uint8).ravel()
    value = np.ascontiguousarray(value, np.uint64).ravel()
    out = np.zeros((int(width.sum(dtype=np.int64)) + 7) // 8, np.uint8)
    _writer.pack_bits(width, value, out)
    return out


# A table is stored as one byte per token (spec 4.3.2): 0 for a token the table never codes, 1 ..
# MAX_CODE for a frequency of round(2^((code - 1) / LOG_STEPS)), and REST for the one token that takes
# what the others leave of TOTAL. Frequencies on a log scale, 4 steps an octave (19 % apart), take much
# less room than 12-bit counts and code the tokens almost as tightly (docs/compression.md, "Log-scale token
# tables").
LOG_STEPS = 4
MAX_CODE = 1 + LOG_STEPS * PROB_BITS  # a frequency of TOTAL: more than any but a REST entry can take
REST = 255


def code_frequencies(codes: np.ndarray) -> np.ndarray:
    """The frequencies of table codes other than REST (0 for 0 and REST)."""
    codes = np.asarray(codes, np.int64)
    f = np.rint(2.0 ** ((np.clip(codes, 1, MAX_CODE) - 1) / LOG_STEPS)).astype(np.int64)
    return np.where((codes > 0) & (codes <= MAX_CODE), f, 0)


def quantize_tables(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The writer's tables for token counts ``[T, ALPHABET]``: their codes (uint8) and the frequencies
    they decode to. Each counted token gets the code nearest its share of TOTAL on the log scale,
    the most counted one REST; where that would leave REST outside 1 .. MAX_FREQ, the largest other
    entry (or, with none, the next token) takes up or gives back the difference, as nearly as its
    codes allow, until it does not."""
    counts = np.asarray(counts, np.int64)
    total = counts.sum(axis=1, keepdims=True)
    share = np.maximum(counts * TOTAL / np.maximum(total, 1), 1.0)
    codes = np.where(counts > 0, np.minimum(1 + np.rint(LOG_STEPS * np.log2(share)), MAX_CODE), 0).astype(np.int64)
    rows = np.flatnonzero(total[:, 0])
    top = np.argmax(counts, axis=1)
    codes[rows, top[rows]] = 0
    rest = TOTAL - code_frequencies(codes).sum(axis=1)
    for t in rows[(rest[rows] < 1) | (rest[rows] > MAX_FREQ)]:  # a dominant or a flat table
        row = codes[t]
        while not 1 <= rest[t] <= MAX_FREQ:
            f = code_frequencies(row)
            j = int(np.argmax(f)) if f.any() else (top[t] + 1) % ALPHABET
            # the code of j whose frequency takes up (or gives back) what the remainder is out by
            want = f[j] + (rest[t] - MAX_FREQ if rest[t] > MAX_FREQ else rest[t] - 1)
            step = np.ceil if rest[t] > MAX_FREQ else np.floor
            row[j] = int(np.clip(1 + step(LOG_STEPS * np.log2(max(want, 1))), 1, MAX_CODE))
            if code_frequencies(row[j]) == f[j]:  # no code lies between: move by one
                row[j] += 1 if rest[t] > MAX_FREQ else -1
            rest[t] = TOTAL - code_frequencies(row).sum()
    codes[rows, top[rows]] = REST
    return codes.astype(np.uint8), table_frequencies(codes, "the writer's tables")


def table_frequencies(codes: np.ndarray, where: str) -> np.ndarray:
    """The frequencies ``[T, ALPHABET]`` of stored table codes (spec 4.3.2). A row is all zero (a
    table never used) or has exactly one REST, whose frequency is what the others leave of TOTAL and
    must lie in 1 .. MAX_FREQ; any other code makes the file corrupt."""
    codes = np.asarray(codes, np.int64)
    used = codes.any(axis=1)
    if ((codes > MAX_CODE) & (codes != REST)).any() or ((codes == REST).sum(axis=1) != used).any():
        raise InvalidContentError(f"{where}: a table code is out of range, or a table lacks its one remainder entry")
    freq = code_frequencies(codes)
    rest = TOTAL - freq.sum(axis=1)
    if ((rest < 1) | (rest > MAX_FREQ))[used].any():
        raise InvalidContentError(f"{where}: a table's entries leave its remainder outside 1 .. {MAX_FREQ}")
    freq[codes == REST] = rest[used]
    return freq


def estimate_bytes(r: np.ndarray) -> float:
    """Order-0 size estimate of signed residuals ``r`` under this coder, which zigzag-codes them: token
    entropy plus extra bits. Counted without forming the tokens: the writer calls it often."""
    r = np.asarray(r, np.int64).ravel()
    half = DIRECT // 2  # residuals -half .. half - 1 are the direct tokens 2r (r >= 0) and -2r - 1 (r < 0)
    near = np.bincount(np.clip(r, -half - 1, half) + half + 1, minlength=DIRECT + 2)  # 0 and DIRECT + 1: beyond
    counts = np.zeros(ALPHABET, np.int64)
    counts[0:DIRECT:2] = near[half + 1:DIRECT + 1]
    counts[1:DIRECT:2] = near[half:0:-1]
    if near[0] or near[-1]:
        far = zigzag(r[(r < -half) | (r >= half)])
        counts[DIRECT:] = np.bincount(bit_length(far) - 5, minlength=ALPHABET - DIRECT)
    p = counts[counts > 0] / r.size
    extra_bits = int(counts @ TOKEN_WIDTHS.astype(np.int64))
    return float(-(counts[counts > 0] * np.log2(p)).sum() + extra_bits) / 8


class Tables:
    """Frequency tables ``[T, ALPHABET]`` with their cumulative starts, flattened."""

    def __init__(self, freq: np.ndarray, where: str) -> None:
        freq = np.asarray(freq, np.int64)
        sums = freq.sum(axis=1)
        if freq.min(initial=0) < 0 or freq.max(initial=0) > MAX_FREQ or not np.isin(sums, (0, TOTAL)).all():
            raise InvalidContentError(f"{where}: every frequency table must sum to {TOTAL} (or be empty) with no "
                                      f"entry above {MAX_FREQ}")
        # the fewest bits any symbol can cost: what bounds the symbols a stream of a given size holds
        used = freq.max(axis=1)[sums > 0]
        self.min_bits = float(np.log2(TOTAL / used.max())) if used.size else float("inf")
        self.freq = freq.astype(np.uint32)
        self.flat_freq = self.freq.ravel()
        self.flat_start = (np.cumsum(freq, axis=1) - freq).astype(np.uint32).ravel()


def encode(sym: np.ndarray, table: np.ndarray, active: np.ndarray, tables: Tables) -> tuple[np.ndarray, np.ndarray]:
    """Code steps of symbols ``sym [N, L]`` under ``table [N, L]``; lanes ``>= active[n]`` are idle at
    step ``n``. Returns the lanes' initial states for the decoder (uint32 ``[L]``) and the words
    (compiled: :func:`._writer.encode_rans`)."""
    states = np.empty(sym.shape[1], np.uint32)
    words = np.empty(sym.size, np.uint16)
    start = _writer.encode_rans(np.ascontiguousarray(sym, np.uint8), np.ascontiguousarray(table, np.int32),
                                np.ascontiguousarray(active, np.int64), tables.flat_freq, tables.flat_start,
                                states, words)
    return states, words[start:].copy()


def check_budget(symbols: int, words: int, lanes: int, tables: Tables, where: str) -> None:
    """Refuse, before decoding, more symbols than ``lanes`` states and ``words`` 16-bit words can hold:
    each costs at least ``tables.min_bits``. A crafted stream can thus not make a decoder loop for long."""
    held = 16 * words + 32 * lanes
    if symbols * tables.min_bits > held + 64:
        raise InvalidContentError(f"{where}: {symbols} symbols cannot fit in {held} bits of rANS stream")
