"""A multi-lane rANS entropy coder with static context tables (spec 4.3.2): the writer, in vectorized
numpy; the reader is compiled (:func:`._native.decode_residuals`).

Unsigned integers are split into a token (coded with rANS under a frequency table that the caller
picks per symbol: its context) and raw extra bits. ``L`` lanes each hold a rANS state and code their
own symbols; all lanes share one stream of 16-bit words, so one step of the coder handles one
symbol of every lane with a few array operations.

Token of ``u``: ``u`` itself below ``DIRECT``; otherwise ``DIRECT + bitlen(u) - 5`` followed by the
``bitlen(u) - 1`` bits of ``u`` below its leading one (MSB first).
"""

from __future__ import annotations

import numpy as np

from . import _native
from .errors import InvalidContentError
from .quantize import zigzag

DIRECT = 16
ALPHABET = DIRECT + 60  # bit lengths 5 .. 64
PROB_BITS = 12
TOTAL = 1 << PROB_BITS
LOW = 1 << 16  # states live in [LOW, 2^32); renormalization moves 16-bit words
MAX_FREQ = TOTAL - 16  # every symbol costs at least log2(TOTAL / MAX_FREQ) bits: no free symbols
NO_SYMBOL = 255


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
    sym = np.where(u < DIRECT, u, 0).astype(np.uint8)
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
    width = np.ascontiguousarray(width.ravel(), np.uint8)
    value = np.ascontiguousarray(value.ravel(), np.uint64)
    out = np.zeros((int(width.sum(dtype=np.int64)) + 7) // 8, np.uint8)
    _native.pack_bits(width, value, out)
    return out


def normalize(counts: np.ndarray) -> np.ndarray:
    """Frequency tables ``[T, ALPHABET]`` summing to ``TOTAL`` (all-zero rows stay zero), every
    counted symbol at least 1 and none above ``MAX_FREQ``: the writer's choice (any such table decodes)."""
    counts = np.asarray(counts, np.int64)
    total = counts.sum(axis=1, keepdims=True)
    freq = np.where(counts > 0, np.maximum(1, counts * TOTAL // np.maximum(total, 1)), 0)
    for t in np.flatnonzero(total[:, 0]):
        row = freq[t]
        order = np.argsort(-row, kind="stable")
        diff = TOTAL - int(row.sum())  # rounding: the largest entries absorb it
        if diff > 0:
            row[order[0]] += diff
        for j in order:
            if diff >= 0:
                break
            take = min(int(row[j]) - 1, -diff)
            row[j] -= take
            diff += take
        top = order[0]
        if row[top] > MAX_FREQ:  # no symbol may be (nearly) free: see check_budget
            other = order[1] if row[order[1]] > 0 else (top + 1) % ALPHABET
            row[other] += row[top] - MAX_FREQ
            row[top] = MAX_FREQ
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
    """Frequency tables ``[T, ALPHABET]`` with their cumulative starts and slot lookup, flattened."""

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
        slot = np.full((len(freq), TOTAL), NO_SYMBOL, np.uint8)
        for t in np.flatnonzero(sums):
            slot[t] = np.repeat(np.arange(ALPHABET, dtype=np.uint8), freq[t])
        self.flat_slot = slot.ravel()


def encode(sym: np.ndarray, table: np.ndarray, active: np.ndarray, tables: Tables) -> tuple[np.ndarray, np.ndarray]:
    """Code steps of symbols ``sym [N, L]`` under ``table [N, L]``; lanes ``>= active[n]`` are idle at
    step ``n``. Returns the lanes' initial states for the decoder (uint32 ``[L]``) and the words."""
    n_steps, lanes = sym.shape
    x = np.full(lanes, LOW, np.uint64)
    flat = table.astype(np.int64) * ALPHABET + sym
    out = []
    for n in range(n_steps - 1, -1, -1):
        a = int(active[n])
        xs = x[:a]
        f = tables.flat_freq[flat[n, :a]].astype(np.uint64)
        emit = xs >= f << np.uint64(20)  # ((LOW >> PROB_BITS) << 16) * f
        if emit.any():
            out.append((xs[emit] & np.uint64(0xFFFF))[::-1])
            xs[emit] >>= np.uint64(16)
        x[:a] = ((xs // f) << np.uint64(PROB_BITS)) + xs % f + tables.flat_start[flat[n, :a]]
    words = np.concatenate(out)[::-1] if out else np.zeros(0, np.uint64)
    return x.astype(np.uint32), words.astype(np.uint16)


def check_budget(symbols: int, words: int, lanes: int, tables: Tables, where: str) -> None:
    """Refuse, before decoding, more symbols than ``lanes`` states and ``words`` 16-bit words can hold:
    each costs at least ``tables.min_bits``. A crafted stream can thus not make a decoder loop for long."""
    held = 16 * words + 32 * lanes
    if symbols * tables.min_bits > held + 64:
        raise InvalidContentError(f"{where}: {symbols} symbols cannot fit in {held} bits of rANS stream")
