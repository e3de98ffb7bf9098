"""A statistical prior of strand shapes: a PCA basis of strands resampled to ``P`` points, made
root-relative, in metres, and turned into a canonical frame (first segment along +x, the up axis's
component across it along +y), so that the basis describes shape, not placement.

The package ships a basis fitted on the built-in synthetic styles (``data/strand_prior.npz``,
made by :func:`fit_builtin`); a basis fitted on other models (real ones, say) is made with
``cgh fit-strand-prior MODELS... -o FILE`` and passed to ``cgh reconstruct --prior FILE``:
it is written where the user says, never into the package.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cghair_format.strands import Strands, resample

from .hull import ReconstructError

POINTS = 32
COMPONENTS = 16
MAX_STRANDS_PER_MODEL = 3000  # strands drawn from each model for the fit
BUILTIN = Path(__file__).with_name("data") / "strand_prior.npz"
BUILTIN_STYLES = ("straight", "wavy", "curly", "coily", "short", "long", "ponytail")


@dataclass
class StrandPrior:
    mean: np.ndarray  # [P*3] metres, canonical frame
    components: np.ndarray  # [K, P*3] orthonormal rows
    stddev: np.ndarray  # [K] metres, the spread of each coefficient
    sources: list[str]

    @property
    def points(self) -> int:
        return self.mean.size // 3

    def save(self, path: str | Path) -> None:
        np.savez_compressed(path, mean=self.mean.astype(np.float32), components=self.components.astype(np.float32),
                            stddev=self.stddev.astype(np.float32), sources=np.array(self.sources))

    @classmethod
    def load(cls, path: str | Path = BUILTIN) -> StrandPrior:
        try:
            with np.load(path) as z:
                prior = cls(z["mean"].astype(np.float64), z["components"].astype(np.float64),
                            z["stddev"].astype(np.float64), [str(s) for s in z["sources"]])
        except (OSError, ValueError, KeyError) as exc:
            raise ReconstructError(f"{path}: not a strand prior file ({exc})") from None
        if prior.components.shape[1:] != prior.mean.shape or prior.mean.size % 3:
            raise ReconstructError(f"{path}: strand prior arrays have inconsistent shapes")
        return prior


def canonical_frames(strands: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``[S, 3, 3]`` rotations whose rows are the canonical axes of each strand ``[S, P, 3]``."""
    t = strands[:, 1] - strands[:, 0]
    t = t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    u = np.broadcast_to(np.asarray(up, np.float64), t.shape)
    side = u - np.einsum("ij,ij->i", u, t)[:, None] * t
    weak = np.linalg.norm(side, axis=1) < 1e-6  # first segment along up: any perpendicular
    side[weak] = np.cross(t[weak], [1.0, 0.0, 0.0])
    side = side / np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-12)
    return np.stack([t, side, np.cross(t, side)], 1)


def to_canonical(strands: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Root-relative strands in their canonical frames, flattened ``[S, P*3]``, and the frames."""
    r = canonical_frames(strands, up)
    local = np.einsum("sij,spj->spi", r, strands - strands[:, :1])
    return local.reshape(len(strands), -1), r


def from_canonical(flat: np.ndarray, frames: np.ndarray, roots: np.ndarray) -> np.ndarray:
    local = flat.reshape(len(flat), -1, 3)
    return np.einsum("sji,spj->spi", frames, local) + roots[:, None]


def _up(strands: Strands) -> np.ndarray:
    return np.array([0.0, 1.0, 0.0]) if strands.up_axis == "Y" else np.array([0.0, 0.0, 1.0])


def fit_prior(models: list[tuple[str, Strands]], components: int = COMPONENTS, points: int = POINTS,
              seed: int = 0) -> StrandPrior:
    """PCA of up to ``MAX_STRANDS_PER_MODEL`` strands of each model (named for the record)."""
    rng = np.random.default_rng(seed)
    rows = []
    for _, s in models:
        res = resample(s, points)
        arr = res.to_array().astype(np.float64) * s.meters_per_unit
        pick = rng.choice(len(arr), min(len(arr), MAX_STRANDS_PER_MODEL), replace=False)
        rows.append(to_canonical(arr[pick], _up(s))[0])
    x = np.concatenate(rows)
    if len(x) <= components:
        raise ReconstructError(f"a {components}-component prior needs more than {components} strands, got {len(x)}")
    mean = x.mean(0)
    _, sv, vt = np.linalg.svd(x - mean, full_matrices=False)
    return StrandPrior(mean, vt[:components], sv[:components] / np.sqrt(len(x) - 1), [n for n, _ in models])


def fit_builtin() -> StrandPrior:
    """The shipped basis: every built-in synthetic style, 2000 strands each."""
    from cghair_format.synth import synthesize

    return fit_prior([(f"synth:{name}", synthesize(name, n_strands=2000, n_points=POINTS, seed=7))
                      for name in BUILTIN_STYLES])


def project(strands: Strands, prior: StrandPrior, up: np.ndarray, clamp: float = 3.0) -> Strands:
    """Each strand replaced by its nearest shape in the basis (coefficients within ``clamp``
    standard deviations), at its own root and frame."""
    res = resample(strands, prior.points)
    arr = res.to_array().astype(np.float64) * strands.meters_per_unit
    flat, frames = to_canonical(arr, up)
    coef = (flat - prior.mean) @ prior.components.T
    coef = np.clip(coef, -clamp * prior.stddev, clamp * prior.stddev)
    back = from_canonical(prior.mean + coef @ prior.components, frames, arr[:, 0]) / strands.meters_per_unit
    return Strands.from_array(back.astype(np.float32), meters_per_unit=strands.meters_per_unit,
                              up_axis=strands.up_axis)


def residual(strands: np.ndarray, prior: StrandPrior, up: np.ndarray) -> np.ndarray:
    """Distance (metres, RMS per point) of each strand ``[S, P, 3]`` in metres from the basis."""
    flat, _ = to_canonical(strands, up)
    d = flat - prior.mean
    r = d - (d @ prior.components.T) @ prior.components
    return np.sqrt((r * r).reshape(len(r), -1, 3).sum(-1).mean(1))
