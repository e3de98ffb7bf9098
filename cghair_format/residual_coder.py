"""Entropy coding of the STRD residuals with context tables and rANS (spec 4.3.2).

The residual arrays (base, then each level; ``[S, n_a, 3]`` integers each) are zigzag-coded and
split into tokens and extra bits (:mod:`.rans`). A token's table depends on its array, its channel
and a context: the bit length of the previous token of the same strand, array and channel, and the
largest bit length among the channels already coded at the same sample. Strands are coded in
blocks of ``L`` lanes, one strand per lane; within a block, column by column, channel u, v, delta.
"""

from __future__ import annotations

import numpy as np

from . import _native, rans
from .errors import InvalidContentError, TruncatedError
from .quantize import zigzag
from .streams import StreamReader, StreamWriter

LANES = 4096  # at most; each lane costs its 4-byte state ...
MIN_BLOCKS = 8  # ... so smaller assets use fewer lanes, S / 8 rounded up
PREV_CLASSES, OTHER_CLASSES = 8, 4
CONTEXTS = PREV_CLASSES * OTHER_CLASSES


def _plan(widths: list[int], strands: int):
    """Per column: its array and whether it starts one; the lanes; the blocks' active lane counts."""
    column_array = np.repeat(np.arange(len(widths)), widths)
    first = np.r_[True, column_array[1:] != column_array[:-1]]
    lanes = min(LANES, -(-strands // MIN_BLOCKS))
    blocks = -(-strands // lanes)
    active = np.minimum(lanes, strands - lanes * np.arange(blocks))
    return column_array, first, lanes, active


def _table(array: np.ndarray | int, ch: int, prev: np.ndarray, other: np.ndarray) -> np.ndarray:
    return ((array * 3 + ch) * CONTEXTS + np.minimum(prev, PREV_CLASSES - 1) * OTHER_CLASSES
            + np.minimum(other, OTHER_CLASSES - 1))


def _to_steps(a: np.ndarray, lanes: int, blocks: int) -> np.ndarray:
    """``[S, N, 3]`` -> ``[blocks, N, 3, lanes]`` (strand ``b * lanes + lane``), zero padded."""
    s, n = a.shape[:2]
    pad = np.zeros((blocks * lanes, n, 3), a.dtype)
    pad[:s] = a
    return pad.reshape(blocks, lanes, n, 3).transpose(0, 2, 3, 1)


def write_residuals(w: StreamWriter, arrays: list[np.ndarray]) -> None:
    """Append the coded residual arrays to ``w``: tables, lane states, words, extra bits."""
    s = arrays[0].shape[0]
    widths = [a.shape[1] for a in arrays]
    column_array, first, lanes, active = _plan(widths, s)
    sym, extra = rans.tokens(zigzag(np.concatenate(arrays, axis=1)))
    bits = rans.TOKEN_BITS[sym]
    prev = np.zeros_like(bits)
    prev[:, 1:] = bits[:, :-1]
    prev[:, first] = 0
    other = np.zeros_like(bits)
    other[..., 1] = bits[..., 0]
    other[..., 2] = np.maximum(bits[..., 0], bits[..., 1])
    table = _table(column_array[None, :, None].astype(np.int32), np.arange(3, dtype=np.int32)[None, None, :],
                   prev, other)
    n_tables = len(widths) * 3 * CONTEXTS
    counts = np.bincount((table * rans.ALPHABET + sym).ravel(), minlength=n_tables * rans.ALPHABET)  # int32
    tables = rans.Tables(rans.normalize(counts.reshape(n_tables, rans.ALPHABET)), "STRD")
    blocks = len(active)
    step_sym = _to_steps(sym, lanes, blocks).reshape(-1, lanes)
    step_table = _to_steps(table, lanes, blocks).reshape(-1, lanes)
    step_active = np.repeat(active, step_sym.shape[0] // blocks)
    states, words = rans.encode(step_sym, step_table, step_active, tables)
    w.array(tables.freq.astype(np.uint16), shuffle=True)
    w.array(states)
    w.array(words)
    # in step order; the padding lanes of the last block have width 0 and add no bits
    w.array(rans.pack_bits(rans.token_widths(step_sym), _to_steps(extra, lanes, blocks)))


def read_residuals(r: StreamReader, strands: int, widths: list[int]) -> np.ndarray:
    """Inverse of :func:`write_residuals`: the residual arrays side by side, ``[S, sum(widths), 3]``
    (int64), decoded by the compiled :func:`._native.decode_residuals` (one strand per lane, as the
    spec's step order has it)."""
    column_array, first, lanes, _ = _plan(widths, strands)
    n_tables = len(widths) * 3 * CONTEXTS
    tables = rans.Tables(r.array((n_tables, rans.ALPHABET), "token tables", ("<u2",)), "STRD token tables")
    states = r.array((lanes,), "rANS states", ("<u4",)).astype(np.uint32)
    words = r.array((None,), "rANS words", ("<u2",)).astype(np.uint16)
    extra_bits = r.array((None,), "extra bits", ("|u1",)).astype(np.uint8)
    if (states < rans.LOW).any():
        raise InvalidContentError(f"STRD: a lane's initial rANS state is below {rans.LOW}", chunk="STRD")
    n = len(column_array)
    rans.check_budget(strands * n * 3, len(words), lanes, tables, "STRD")
    values = np.empty((strands, n, 3), np.int64)
    fault = _native.decode_residuals(tables.flat_slot, tables.flat_freq, tables.flat_start, states, words,
                                     extra_bits, column_array.astype(np.int64), first.astype(np.uint8), lanes,
                                     np.empty((strands, n, 3), np.uint8), values)
    if fault:
        error = TruncatedError if fault == _native.TRUNCATED else InvalidContentError
        raise error(f"STRD: {_native.FAULTS[fault]}", chunk="STRD")
    return values
