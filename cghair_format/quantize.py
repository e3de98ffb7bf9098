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
    x = np.asarray(x, np.int64)
    return ((x << 1) ^ (x >> 63)).view(np.uint64)


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
    plan = np.array(base), tuple(levels)
    for a in (plan[0], *(a for level in plan[1] for a in level)):
        a.flags.writeable = False  # cached (every later call gets these arrays): an edit raises, not spreads
    return plan


def hier_encode(y: np.ndarray, base_stride: int, lowerable: np.ndarray | None = None
                ) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Code sequences ``y [S, n]`` (already in quantization-step units) along axis 1.

    Base samples: DPCM with linear extrapolation of the previous two reconstructed base samples,
    residuals ``round(y - pred)``, reconstruction integer. Refinement samples: ``pred`` = Lagrange
    interpolation of reconstructed neighbours, residual ``r = round(y - pred)``, reconstruction
    ``pred + r`` (no re-rounding, so a sample within half a step of its prediction costs a zero).
    Every reconstructed sample is within 0.5 of ``y``, except where ``lowerable [S, n]`` (bool) is
    set: there it may reconstruct anywhere in ``[-0.5, y + 0.5]`` (what a reader clamping at 0 decodes
    to at most its own value; ``y >= 0`` keeps that range a step wide) and takes the residual nearest
    zero that lands there. Returns the base residuals
    ``[S, nb]``, one residual array ``[S, L]`` per level (all int64) and the reconstruction ``[S, n]``
    (float64), as :func:`hier_decode` gives it.
    """
    yt = np.asarray(y, np.float64).T  # sample-major: each sample of every sequence is one contiguous row
    base, levels = level_plan(yt.shape[0], base_stride)
    free = None if lowerable is None else np.asarray(lowerable, bool).T

    def residual(i, pred: np.ndarray) -> np.ndarray:
        r = np.rint(yt[i] - pred)
        if free is None:
            return r
        nearest_zero = np.clip(0.0, np.ceil(-0.5 - pred), np.floor(yt[i] + 0.5 - pred))
        return np.where(free[i], nearest_zero, r)

    rec = np.zeros(yt.shape)
    base_res = np.zeros((len(base), yt.shape[1]), np.int64)
    for j, i in enumerate(base):
        pred = base_prediction(rec, base, j)
        r = residual(i, pred)
        base_res[j] = r
        rec[i] = pred + r
    out = []
    for idx, nb, wt in levels:
        pred = _interp(rec, nb, wt)
        r = residual(idx, pred)
        rec[idx] = pred + r
        out.append(np.ascontiguousarray(r.T.astype(np.int64)))
    return np.ascontiguousarray(base_res.T), out, np.ascontiguousarray(rec.T)


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

# The last MLP layer's rows come in colour triples (R, G, B of one SH coefficient of one Gaussian).
# They are stored in this orthonormal basis: grey, red - blue, and green against the two. A trained
# model's triples are mostly grey (their R, G and B rows correlate strongly), so the other two rows are
# small and cost few bits at the same step (spec 4.4; docs/compression.md, "MLP colour basis and steps").
COLOUR_BASIS = np.array([[1.0, 1.0, 1.0], [1.0, 0.0, -1.0], [1.0, -2.0, 1.0]]) / np.sqrt([[3.0], [2.0], [6.0]])
# A bias's step is its layer's over this: a bias's error reaches every output of its row alike, while
# the weights' errors, times varied activations, partly cancel; on a sixteenth of the step the biases'
# error no longer shows in the render (docs/compression.md, "MLP colour basis and steps")
BIAS_STEP_DIVISOR = 16


def weight_step(w: np.ndarray, fraction: float) -> float:
    """The step of one array of weights: ``fraction`` of its root mean square, as a float32 (1 for an
    all-zero array)."""
    rms = float(np.sqrt(np.mean(np.square(np.asarray(w, np.float64))))) if np.size(w) else 0.0
    return float(np.float32(fraction * rms)) if rms > 0 else 1.0


def to_colour_basis(rows: np.ndarray) -> np.ndarray:
    """Rows ``[3T, ...]`` (colour triples) in :data:`COLOUR_BASIS`, float64."""
    r = np.asarray(rows, np.float64)
    return np.einsum("kc,tc...->tk...", COLOUR_BASIS, r.reshape(-1, 3, *r.shape[1:])).reshape(r.shape)


def from_colour_basis(rows: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_colour_basis` (the basis is orthonormal: its transpose), float64, summed over
    the basis rows in order as spec 4.4 writes it (einsum does not promise an order)."""
    r = np.asarray(rows, np.float64).reshape(-1, 3, *np.shape(rows)[1:])
    c = COLOUR_BASIS
    out = np.stack([c[0, ch] * r[:, 0] + c[1, ch] * r[:, 1] + c[2, ch] * r[:, 2] for ch in range(3)], axis=1)
    return out.reshape(np.shape(rows))


def steps_encode(w: np.ndarray, step: float) -> np.ndarray:
    """Integers ``round(w / step)``; each value decodes within ``step / 2``."""
    return np.rint(np.asarray(w, np.float64) / step).astype(np.int64)


def steps_decode(q: np.ndarray, step: float) -> np.ndarray:
    """``q * step`` in float64."""
    return np.asarray(q, np.float64) * step


def weight_steps(codebooks: np.ndarray, layers: list[tuple[np.ndarray, np.ndarray]], fraction: float,
                 mlp_fraction: float | None = None) -> list[float]:
    """One step per array: the codebooks' (:func:`weight_step` at ``fraction``), then each MLP layer's
    (at ``mlp_fraction``, default ``fraction``, of its weights, the last layer's in :data:`COLOUR_BASIS`);
    a layer's biases take a sixteenth of its step."""
    mlp = fraction if mlp_fraction is None else mlp_fraction
    return [weight_step(codebooks, fraction)] + [
        weight_step(to_colour_basis(w) if j == len(layers) - 1 else w, mlp) for j, (w, _) in enumerate(layers)]


def weights_encode(steps: list[float], codebooks: np.ndarray, layers: list[tuple[np.ndarray, np.ndarray]]
                   ) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """Codebooks and MLP layers ``(weight, bias)`` as integers times the arrays' ``steps``
    (:func:`weight_steps`), the last layer in :data:`COLOUR_BASIS`: the codebook integers and each
    layer's ``(weight, bias)`` integers."""
    coded = []
    for j, ((w, b), step) in enumerate(zip(layers, steps[1:], strict=True)):
        if j == len(layers) - 1:
            w, b = to_colour_basis(w), to_colour_basis(b)
        coded.append((steps_encode(w, step), steps_encode(b, step / BIAS_STEP_DIVISOR)))
    return steps_encode(codebooks, steps[0]), coded


def weights_decode(steps: list[float], codebooks: np.ndarray, layers: list[tuple[np.ndarray, np.ndarray]]
                   ) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """Inverse of :func:`weights_encode`: the codebooks and ``(weight, bias)`` per layer, float32
    (each value of the codebooks and hidden layers within half its step of the writer's; of the last
    layer, within ``0.85`` step, the basis's largest column sum over 2)."""
    out = []
    for j, ((w, b), step) in enumerate(zip(layers, steps[1:], strict=True)):
        w, b = steps_decode(w, step), steps_decode(b, step / BIAS_STEP_DIVISOR)
        if j == len(layers) - 1:
            w, b = from_colour_basis(w), from_colour_basis(b)
        out.append((_float32(w), _float32(b)))
    return _float32(steps_decode(codebooks, steps[0])), out


def _float32(a: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore", invalid="ignore"):  # a corrupt step gives inf, which the reader refuses
        return a.astype(np.float32)
