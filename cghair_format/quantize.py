"""Quantizers and predictors: pure numpy functions with exact inverses (spec: "Quantization").

Nothing here knows about files. Each ``*_encode`` returns integers; the matching ``*_decode`` is
the normative reconstruction the spec's pseudocode describes.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

# --- integer mappings --------------------------------------------------------------------------

def zigzag(x: np.ndarray) -> np.ndarray:
    """Signed to unsigned: 0, -1, 1, -2, 2 ... -> 0, 1, 2, 3, 4 ..."""
    x = x.astype(np.int64)
    return ((x << 1) ^ (x >> 63)).astype(np.uint64)


def unzigzag(u: np.ndarray) -> np.ndarray:
    u = u.astype(np.uint64)
    return ((u >> np.uint64(1)).astype(np.int64)) ^ -((u & np.uint64(1)).astype(np.int64))


# --- hierarchical interpolating predictor along strands ------------------------------------------

TAPS = (2, 4, 6, 8)  # interpolation neighbours a level may use; 4 unless a plan says otherwise


@lru_cache(maxsize=64)
def level_plan(n: int, base_stride: int, taps: tuple[int, ...] | None = None
               ) -> tuple[np.ndarray, tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]]:
    """The coding order of ``n`` samples: base indices, then refinement levels.

    Base: ``0, B, 2B, ...`` and ``n - 1``. Each later level (stride ``h = B/2, B/4, ..., 1``) adds the
    indices ``i`` with ``i mod 2h == h``, ``i < n - 1``, predicted by Lagrange interpolation through
    the (up to) ``T / 2`` nearest known indices on each side, ``T = taps[level]`` (one of TAPS; 4 for
    every level when ``taps`` is None). Returns the base indices and, per level, ``(indices [L],
    neighbour indices [L, W], weights [L, W])``, ``W`` the largest ``T`` (unused slots have weight 0).
    """
    if taps is not None and (len(taps) != len(level_plan(n, base_stride)[1]) or not set(taps) <= set(TAPS)):
        raise ValueError(f"taps {taps} do not fit the {len(level_plan(n, base_stride)[1])} levels of {n} points "
                         f"(each one of {TAPS})")
    width = 4 if not taps else max(taps)
    base = sorted(set(range(0, n, base_stride)) | {n - 1})
    known = np.zeros(n, bool)
    known[base] = True
    levels = []
    h = base_stride // 2
    while h >= 1:
        idx = [i for i in range(h, n - 1, 2 * h) if not known[i]]
        if idx:
            half = (4 if taps is None else taps[len(levels)]) // 2
            kn = np.flatnonzero(known)
            nb = np.zeros((len(idx), width), np.int64)
            wt = np.zeros((len(idx), width), np.float64)
            for row, i in enumerate(idx):
                pos = np.searchsorted(kn, i)
                pts = list(kn[max(0, pos - half):pos]) + list(kn[pos:pos + half])
                for col, j in enumerate(pts):
                    w = 1.0
                    for m in pts:
                        if m != j:
                            w *= (i - m) / (j - m)
                    nb[row, col], wt[row, col] = j, w
            levels.append((np.array(idx), nb, wt))
            known[idx] = True
        h //= 2
    assert known.all()
    return np.array(base), tuple(levels)


def hier_encode(y: np.ndarray, base_stride: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Code sequences ``y [S, n]`` (already in quantization-step units) along axis 1.

    Base samples: DPCM with linear extrapolation of the previous two reconstructed base samples,
    residuals ``round(y - pred)``, reconstruction integer. Refinement samples: ``pred`` = Lagrange
    interpolation of reconstructed neighbours, residual ``r = round(y - pred)``, reconstruction
    ``pred + r`` (no re-rounding, so a sample within half a step of its prediction costs a zero).
    Every reconstructed sample is within 0.5 of ``y``. Returns the base residuals ``[S, nb]`` and
    one residual array ``[S, L]`` per level, all int64.
    """
    yt = np.asarray(y, np.float64).T  # sample-major: each sample of every sequence is one contiguous row
    base, levels = level_plan(yt.shape[0], base_stride)
    rec = np.zeros(yt.shape)
    base_res = np.zeros((len(base), yt.shape[1]), np.int64)
    for j, i in enumerate(base):
        pred = base_prediction(rec, base, j)
        r = np.rint(yt[i] - pred)
        base_res[j] = r
        rec[i] = pred + r
    out = []
    for idx, nb, wt in levels:
        pred = _interp(rec, nb, wt)
        r = np.rint(yt[idx] - pred)
        rec[idx] = pred + r
        out.append(np.ascontiguousarray(r.T.astype(np.int64)))
    return np.ascontiguousarray(base_res.T), out


def hier_decode(base_res: np.ndarray, level_res: list[np.ndarray], n: int, base_stride: int) -> np.ndarray:
    """Inverse of :func:`hier_encode`: the reconstructed samples ``[S, n]`` (float64, step units)."""
    base, levels = level_plan(n, base_stride)
    if len(levels) != len(level_res) or base_res.shape[1] != len(base):
        raise ValueError("residual streams do not match the level plan")
    rec = np.zeros((n, base_res.shape[0]), np.float64)  # sample-major, as in hier_encode
    for j, i in enumerate(base):
        rec[i] = base_prediction(rec, base, j) + base_res[:, j]
    for (idx, nb, wt), r in zip(levels, level_res, strict=True):
        rec[idx] = _interp(rec, nb, wt) + r.T
    return np.ascontiguousarray(rec.T)


def base_prediction(rec: np.ndarray, base: np.ndarray, j: int, order: int = 2) -> np.ndarray | float:
    """Prediction of base sample ``j`` from the samples ``rec [n, ...]`` (sample-major) reconstructed so
    far: 0 for the first, then the previous base sample (order 1) or the linear extrapolation of the
    previous two (order 2, from the third on)."""
    if j == 0:
        return 0.0
    if j == 1 or order == 1:
        return rec[base[j - 1]]
    a, b, c = base[j - 2], base[j - 1], base[j]
    return rec[b] + (rec[b] - rec[a]) * ((c - b) / (b - a))


def _interp(rec: np.ndarray, nb: np.ndarray, wt: np.ndarray) -> np.ndarray:
    """Lagrange predictions ``[L, ...]`` of one level from the sample-major ``rec [n, ...]``."""
    w = wt.reshape(wt.shape + (1,) * (rec.ndim - 1))
    out = rec[nb[:, 0]] * w[:, 0]
    for k in range(1, nb.shape[1]):  # left to right, as the spec sums
        out = out + rec[nb[:, k]] * w[:, k]
    return out


# --- unit vectors ------------------------------------------------------------------------------

def oct_encode(n: np.ndarray, bits: int = 16) -> np.ndarray:
    """Octahedral map of unit vectors ``[..., 3]`` to signed integers ``[..., 2]`` of ``bits`` bits."""
    n = n / np.abs(n).sum(axis=-1, keepdims=True)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    ox = np.where(z >= 0, x, (1 - np.abs(y)) * np.where(x >= 0, 1.0, -1.0))
    oy = np.where(z >= 0, y, (1 - np.abs(x)) * np.where(y >= 0, 1.0, -1.0))
    scale = (1 << (bits - 1)) - 1
    return np.rint(np.stack([ox, oy], axis=-1) * scale).astype(np.int64)


def oct_decode(q: np.ndarray, bits: int = 16) -> np.ndarray:
    """Inverse of :func:`oct_encode`: unit vectors ``[..., 3]`` (float64)."""
    scale = (1 << (bits - 1)) - 1
    ox, oy = q[..., 0] / scale, q[..., 1] / scale
    z = 1 - np.abs(ox) - np.abs(oy)
    t = np.maximum(-z, 0)
    x = ox - np.where(ox >= 0, t, -t)
    y = oy - np.where(oy >= 0, t, -t)
    v = np.stack([x, y, z], axis=-1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# --- soft logits -------------------------------------------------------------------------------

def softmax_levels_encode(logits: np.ndarray, temperature: float, levels: int) -> np.ndarray:
    """Soft logits ``[S, K]`` as what softmax makes of them: ``round(levels * exp((l - max) / tau))``,
    each strand's largest logit at ``levels`` (spec 4.4)."""
    z = (np.asarray(logits, np.float64) - np.max(logits, axis=1, keepdims=True)) / temperature
    return np.rint(levels * np.exp(z)).astype(np.int64)


def softmax_levels_decode(q: np.ndarray, temperature: float, levels: int, floor: float) -> np.ndarray:
    """Inverse of :func:`softmax_levels_encode` up to softmax: ``max(tau * log(q / levels), floor)``;
    every softmax weight is then within ``K / (2 * levels)`` of the original's."""
    with np.errstate(divide="ignore"):  # a stored 0 is the floor
        return np.maximum(temperature * np.log(np.asarray(q) / levels), floor)


# --- weights -----------------------------------------------------------------------------------

def rows_int8_encode(w: np.ndarray, bits: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric ``bits``-bit levels (2..8) per row of ``[R, C]`` in int8: ``w ~ q * scale[row]``.

    ``scale`` is ``absmax / (2^(bits-1) - 1)`` rounded up to a bfloat16 (the top 16 bits of a
    float32, returned as uint16): rounding up keeps every value within the levels, and the scale's
    own precision (2^-8) is far finer than the levels'."""
    w = np.asarray(w, np.float64)
    top = (1 << (bits - 1)) - 1
    scale = (np.abs(w).max(axis=1) / top).astype(np.float32)
    scale = np.where(scale > 0, scale, np.float32(1.0)).astype(np.float32)
    scale_bits = ((scale.view(np.uint32).astype(np.uint64) + 0xFFFF) >> 16).astype(np.uint16)
    q = np.clip(np.rint(w / bfloat16_decode(scale_bits)[:, None]), -top, top).astype(np.int8)
    return q, scale_bits


def bfloat16_decode(b: np.ndarray) -> np.ndarray:
    """float32 values of bfloat16 bit patterns (uint16)."""
    return (np.asarray(b, np.uint32) << 16).view(np.float32)


def rows_int8_decode(q: np.ndarray, scale_bits: np.ndarray) -> np.ndarray:
    """``q * scale[row]`` (float32) with the bfloat16 row scales of :func:`rows_int8_encode`."""
    with np.errstate(over="ignore", invalid="ignore"):  # a corrupt scale gives inf, which validate() refuses
        return (q.astype(np.float32) * bfloat16_decode(scale_bits)[:, None]).astype(np.float32)
