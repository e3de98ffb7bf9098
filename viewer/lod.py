"""Level of detail from the hair's own structure: a subset of whole strands, in a fixed priority.

Every strand gets a priority rank from a fixed integer hash of its index (the same on every
machine and every run, stored nowhere), and a budget of ``N`` Gaussians draws the
``floor(N / segments)`` strands of lowest rank: a larger budget's strands always include a
smaller budget's, so changing the budget adds or removes strands and never reshuffles them (no
flicker). As in Unreal's groom LOD (curve decimation with thickness compensation), the drawn
strands stand in for the ones left out: with a fraction ``f`` of the strands drawn, each drawn
strand stands for ``k = 1 / f`` strands: its thickness is multiplied by ``k^WIDTH_EXPONENT`` and
its opacity becomes ``1 - (1 - o)^(k^(1 - WIDTH_EXPONENT))`` (the transmittance of that many
overlapping strands), so the product of width and optical depth, the hair's coverage, is kept.

The GPU buffers keep the file's order; the preprocess reads the drawn Gaussians through a list of
each SH chunk's strands sorted by rank, so a budget's strands are a prefix of each chunk's list.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .decode import GpuScene

# Share of the compensation taken by the thickness, the rest by the opacity: the share whose reduced
# renders came closest to the full one at a tenth of the strands, and close at a fifth
# (docs/viewer.md, "Level-of-detail compensation").
WIDTH_EXPONENT = 0.75


def strand_ranks(n_strands: int) -> np.ndarray:
    """``rank[s]``: the priority of strand ``s`` (0 is drawn first), a permutation of ``range(n)``.

    The order of a 64-bit mixing hash (splitmix64's finaliser) of the strand index: a
    pseudo-random order, so any prefix is spread evenly over the whole hair.
    """
    with np.errstate(over="ignore"):
        h = np.arange(n_strands, dtype=np.uint64) + np.uint64(0x9E3779B97F4A7C15)
        h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        h ^= h >> np.uint64(31)
    ranks = np.empty(n_strands, np.int64)
    ranks[np.argsort(h, kind="stable")] = np.arange(n_strands)
    return ranks


@dataclass(frozen=True)
class LodPlan:
    """What one frame draws."""

    strands: int  # strands drawn
    gaussians: int  # Gaussians drawn (preprocessed and sorted)
    chunks: tuple[tuple[int, int, int], ...]  # per SH chunk: (list base, Gaussians, first output slot)
    opacity_power: float  # 1 / f
    width: float  # thickness multiplier
    full: bool  # every strand, in the file's order (no indirection, no compensation)


class StrandLod:
    """The priority lists of one :class:`GpuScene` and the plan of a budget."""

    def __init__(self, ctx: Any, scene: GpuScene):
        self.scene = scene
        segs = max(scene.segments, 1)
        self.n_strands = scene.count // segs
        ranks = strand_ranks(self.n_strands)
        lists, self._sorted_ranks = [], []
        for chunk in scene.sh:
            first, last = chunk.first // segs, (chunk.first + chunk.count) // segs
            order = first + np.argsort(ranks[first:last], kind="stable")
            lists.append(order)
            self._sorted_ranks.append(ranks[order])
        self._bases = np.cumsum([0] + [len(x) for x in lists[:-1]]).tolist()
        data = np.concatenate(lists).astype(np.uint32) if lists else np.zeros(1, np.uint32)
        self.buffer = ctx.buffer(data.tobytes() or bytes(16))

    def strands_for(self, budget: int | None) -> int:
        """Strands a budget of Gaussians draws (``None``: all; at least one)."""
        if budget is None:
            return self.n_strands
        return int(min(self.n_strands, max(1, budget // max(self.scene.segments, 1))))

    def plan(self, budget: int | None) -> LodPlan:
        segs = max(self.scene.segments, 1)
        strands = self.strands_for(budget)
        if strands >= self.n_strands:
            return LodPlan(self.n_strands, self.scene.count, (), 1.0, 1.0, True)
        chunks, out = [], 0
        for base, ranks in zip(self._bases, self._sorted_ranks, strict=True):
            n = int(np.searchsorted(ranks, strands)) * segs  # the chunk's strands of rank < strands
            chunks.append((base, n, out))
            out += n
        k = self.n_strands / strands  # strands each drawn strand stands for
        return LodPlan(strands, out, tuple(chunks), k ** (1.0 - WIDTH_EXPONENT), k ** WIDTH_EXPONENT, False)

    def release(self) -> None:
        self.buffer.release()


_SUFFIXES = {"": 1, "k": 1_000, "m": 1_000_000}


def parse_budget(text: str) -> int:
    """A splat budget from the command line: ``250000``, ``250k`` or ``2.5M`` Gaussians."""
    s = str(text).strip().lower().replace("_", "").replace(",", "")
    suffix = s[-1:] if s[-1:] in ("k", "m") else ""
    try:
        value = float(s[:len(s) - len(suffix)]) * _SUFFIXES[suffix]
    except ValueError:
        raise ValueError(f"a budget is a number of Gaussians such as 250000, 250k or 2.5M, got {text!r}") from None
    if not value >= 1 or value != value or value == float("inf"):
        raise ValueError(f"a budget must be at least 1 Gaussian, got {text!r}")
    return int(value)
