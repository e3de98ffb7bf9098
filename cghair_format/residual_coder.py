"""Entropy coding of the STRD residuals with context tables and rANS (spec 4.3.2).

The residual arrays (base, then each level; ``[S, n_a, 3]`` integers each) are zigzag-coded and
split into tokens and extra bits (:mod:`.rans`). A token's table depends on its array, its channel
and a context: the bit length of the previous token of the same strand, array and channel, the
largest bit length among the channels already coded at the same sample, and (with more than one
neighbour class) the bit length of the card neighbour's token at the same sample and channel, where
the neighbour is the strand one lane before; a strand with no such neighbour has a class of its own.
Strands are coded in blocks of ``L`` lanes, one strand per lane; within a block, column by column,
channel u, v, delta.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import zstandard

from . import _decoder, rans
from .errors import InvalidContentError, TruncatedError
from .quantize import zigzag
from .streams import StreamReader, StreamWriter

LANES = 4096  # at most; each lane costs its 4-byte state ...
MIN_BLOCKS = 8  # ... so smaller assets use fewer lanes, S / 8 rounded up
PREV_CLASSES, OTHER_CLASSES = 8, 4
CONTEXTS = PREV_CLASSES * OTHER_CLASSES
# Classes of the card neighbour's token (META quant.neighbour_classes, 1..8; 1: no such context; class 0
# is for strands with no card neighbour before them). The writer takes 5 or 1, whichever its cost
# estimate finds smaller: 5 pays on large files of many alike strands; on small files the larger tables
# cost more than the context saves (docs/compression.md, "Neighbour classes").
NEIGHBOUR_CLASSES = 5
MAX_NEIGHBOUR_CLASSES = 8


def _plan(widths: list[int], strands: int):
    """Per column: its array and whether it starts one; the lanes; the blocks' active lane counts."""
    column_array = np.repeat(np.arange(len(widths)), widths)
    first = np.r_[True, column_array[1:] != column_array[:-1]]
    lanes = min(LANES, -(-strands // MIN_BLOCKS))
    blocks = -(-strands // lanes)
    active = np.minimum(lanes, strands - lanes * np.arange(blocks))
    return column_array, first, lanes, active


def _table(array: np.ndarray | int, ch: int, prev: np.ndarray, other: np.ndarray, neighbour: np.ndarray,
           after: np.ndarray, classes: int) -> np.ndarray:
    """Each token's table (spec 4.3.2); with more than one neighbour class, a strand with no card
    neighbour before it (``after`` false) takes class 0, the others 1 + their neighbour's bit class."""
    e = np.where(after, 1 + np.minimum(neighbour, classes - 2), 0) if classes > 1 else 0
    return ((((array * 3 + ch) * CONTEXTS + np.minimum(prev, PREV_CLASSES - 1) * OTHER_CLASSES
              + np.minimum(other, OTHER_CLASSES - 1)) * classes) + e)


def after_neighbour(strand_card: np.ndarray, lanes: int) -> np.ndarray:
    """Per strand, whether the strand before it in the file is on the same card and one lane before
    it in the same block: whose tokens then give it context (spec 4.3.2)."""
    card = np.asarray(strand_card)
    same = np.r_[False, card[1:] == card[:-1]]
    return same & (np.arange(len(card)) % lanes != 0)


def _to_steps(a: np.ndarray, lanes: int, blocks: int) -> np.ndarray:
    """``[S, N, 3]`` -> ``[blocks, N, 3, lanes]`` (strand ``b * lanes + lane``), zero padded."""
    s, n = a.shape[:2]
    pad = np.zeros((blocks * lanes, n, 3), a.dtype)
    pad[:s] = a
    return pad.reshape(blocks, lanes, n, 3).transpose(0, 2, 3, 1)


class _Coding(NamedTuple):
    """The residual arrays as the coder sees them, with the neighbour class count it chose."""

    sym: np.ndarray  # [S, N, 3] tokens
    extra: np.ndarray  # [S, N, 3] their extra bits
    table: np.ndarray  # [S, N, 3] each token's table
    codes: np.ndarray  # [T, ALPHABET] the tables as stored (rans.quantize_tables) ...
    freq: np.ndarray  # ... and their frequencies
    classes: int
    cost: float  # bytes: tokens, zstd-packed tables and extra bits


def _coding(arrays: list[np.ndarray], strand_card: np.ndarray | None, classes: tuple[int, ...]) -> _Coding:
    """Tokens, contexts and tables of the residual arrays, with the neighbour class count of
    ``classes`` that costs the fewest bytes."""
    s = arrays[0].shape[0]
    widths = [a.shape[1] for a in arrays]
    column_array, first, lanes, _ = _plan(widths, s)
    sym, extra = rans.tokens(zigzag(np.concatenate(arrays, axis=1)))
    bits = rans.TOKEN_BITS[sym]
    prev = np.zeros_like(bits)
    prev[:, 1:] = bits[:, :-1]
    prev[:, first] = 0
    other = np.zeros_like(bits)
    other[..., 1] = bits[..., 0]
    other[..., 2] = np.maximum(bits[..., 0], bits[..., 1])
    neighbour = np.zeros_like(bits)
    after = np.zeros(s, bool)
    if max(classes) > 1:
        after = after_neighbour(strand_card, lanes)
        neighbour[after] = bits[np.flatnonzero(after) - 1]
    extra_bytes = float(rans.token_widths(sym).sum(dtype=np.int64)) / 8

    def table(c: int) -> np.ndarray:
        return _table(column_array[None, :, None].astype(np.int32), np.arange(3, dtype=np.int32)[None, None, :],
                      prev, other, neighbour, after[:, None, None], c)

    # counted once with the most classes: with c classes a token's class is min(its class then, c - 1)
    most = max(classes)
    tables = table(most)
    counts = np.bincount((tables * rans.ALPHABET + sym).ravel(), minlength=len(widths) * 3 * CONTEXTS * most
                         * rans.ALPHABET).reshape(-1, most, rans.ALPHABET)
    best = None
    for c in classes:
        merged = np.concatenate([counts[:, :c - 1], counts[:, c - 1:].sum(axis=1, keepdims=True)], axis=1)
        codes, freq = rans.quantize_tables(merged.reshape(-1, rans.ALPHABET))
        cost = _cost(merged, codes, freq) + extra_bytes
        if best is None or cost < best[1]:
            best = c, cost, codes, freq
    c, cost, codes, freq = best
    return _Coding(sym, extra, tables if c == most else table(c), codes, freq, c, cost)


def coded_bytes(arrays: list[np.ndarray]) -> float:
    """About the bytes :func:`write_residuals` spends on these arrays, with one neighbour class, without
    coding them: the tokens at their tables' code lengths (rANS comes within a few bytes), the tables
    zstd-packed and the extra bits. The writer's yardstick for its per-file choices."""
    return _coding(arrays, None, (1,)).cost


def write_residuals(w: StreamWriter, arrays: list[np.ndarray], strand_card: np.ndarray | None = None,
                    classes: tuple[int, ...] = (1,)) -> int:
    """Append the coded residual arrays to ``w``: tables, lane states, words, extra bits. Of the
    neighbour class counts ``classes`` (more than 1: the card neighbour's tokens give context, with
    ``strand_card`` in file order) the one whose tokens and zstd-packed tables cost the fewest bytes
    is used, and returned."""
    coding = _coding(arrays, strand_card, classes)
    widths = [a.shape[1] for a in arrays]
    _, _, lanes, active = _plan(widths, arrays[0].shape[0])
    tables = rans.Tables(coding.freq, "STRD")
    blocks = len(active)
    step_sym = _to_steps(coding.sym, lanes, blocks).reshape(-1, lanes)
    step_table = _to_steps(coding.table, lanes, blocks).reshape(-1, lanes)
    step_active = np.repeat(active, step_sym.shape[0] // blocks)
    states, words = rans.encode(step_sym, step_table, step_active, tables)
    _put_tables(w, coding.codes)
    w.array(states)
    w.array(words)
    # in step order; the padding lanes of the last block have width 0 and add no bits
    w.array(rans.pack_bits(rans.token_widths(step_sym), _to_steps(coding.extra, lanes, blocks)))
    return coding.classes


def _cost(counts: np.ndarray, codes: np.ndarray, freq: np.ndarray) -> float:
    """Bytes of the tokens counted in ``counts`` coded with the tables ``freq [T, ALPHABET]`` (what rANS
    spends, within a few bytes), plus the tables as stored (``codes``), zstd-packed (level 9)."""
    used = counts.reshape(freq.shape) > 0
    code_bits = float((counts.reshape(freq.shape)[used] * np.log2(rans.TOTAL / freq[used])).sum())
    packed = StreamWriter()
    _put_tables(packed, codes)
    return code_bits / 8 + len(zstandard.ZstdCompressor(level=9).compress(packed.getvalue()))


def _put_tables(w: StreamWriter, codes: np.ndarray) -> None:
    """The tables' record (spec 4.3.2: ``u1[T, 76]`` codes)."""
    w.array(codes.astype(np.uint8))


def read_residuals(r: StreamReader, strand_card: np.ndarray, widths: list[int], classes: int) -> np.ndarray:
    """Inverse of :func:`write_residuals`: the residual arrays side by side, ``[S, sum(widths), 3]``
    (int64), decoded by the compiled :func:`._decoder.decode_residuals` (one strand per lane, as the
    spec's step order has it)."""
    strands = len(strand_card)
    column_array, first, lanes, _ = _plan(widths, strands)
    n_tables = len(widths) * 3 * CONTEXTS * classes
    codes = r.array((n_tables, rans.ALPHABET), "token tables", ("|u1",))
    tables = rans.Tables(rans.table_frequencies(codes, "STRD token tables"), "STRD token tables")
    states = r.array((lanes,), "rANS states", ("<u4",)).astype(np.uint32)
    words = r.array((None,), "rANS words", ("<u2",)).astype(np.uint16)
    extra_bits = r.array((None,), "extra bits", ("|u1",)).astype(np.uint8)
    if (states < rans.LOW).any():
        raise InvalidContentError(f"STRD: a lane's initial rANS state is below {rans.LOW}", chunk="STRD")
    n = len(column_array)
    rans.check_budget(strands * n * 3, len(words), lanes, tables, "STRD")
    values = np.empty((strands, n, 3), np.int64)
    fault = _decoder.decode_residuals(tables.flat_freq, tables.flat_start, states, words,
                                     extra_bits, column_array.astype(np.int64), first.astype(np.uint8), lanes,
                                     after_neighbour(strand_card, lanes).astype(np.uint8), classes,
                                     np.empty((strands, n, 3), np.uint8), values)
    if fault:
        error = TruncatedError if fault == _decoder.TRUNCATED else InvalidContentError
        raise error(f"STRD: {_decoder.FAULTS[fault]}", chunk="STRD")
    return values
