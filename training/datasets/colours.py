"""Hair colours of rendered datasets: the melanin presets (root-to-tip ramps for the splat engine,
melanin and redness for Cycles) and the multi-tone case."""

from __future__ import annotations

import numpy as np

from cghair_format.strands import Strands

from .types import DatasetError

# root / tip RGB of the melanin presets, for the splat engine; Cycles uses (melanin, redness)
PRESETS: dict[str, dict] = {
    "brown": {"root": (0.20, 0.12, 0.07), "tip": (0.38, 0.25, 0.14), "melanin": 0.6, "redness": 0.4},
    "black": {"root": (0.04, 0.035, 0.03), "tip": (0.09, 0.07, 0.06), "melanin": 0.95, "redness": 0.2},
    "blonde": {"root": (0.55, 0.42, 0.25), "tip": (0.80, 0.66, 0.45), "melanin": 0.2, "redness": 0.3},
    "red": {"root": (0.35, 0.10, 0.04), "tip": (0.60, 0.22, 0.09), "melanin": 0.5, "redness": 0.95},
}
# the multi-tone case: tone i of n colours the i-th of n segments along every strand (root first), as
# (eumelanin, pheomelanin) of cghair_format.synth's colour model: dark brown, copper, golden blonde,
# platinum. (`cgh synth --multitone` is that model's dyed-ends look for its own hairstyles; this
# colours any strands, real models included, in hard segments.)
MULTITONE_MELANIN = ((4.0, 0.5), (1.2, 1.6), (0.45, 0.8), (0.12, 0.15))
MULTITONE_JITTER = 0.35  # segment boundaries move by up to this fraction of a segment, per strand
MULTITONE_BRIGHTNESS = 0.15  # per-strand brightness variation (standard deviation)



def strand_colours(strands: Strands, preset: str, seed: int) -> np.ndarray:
    """Per-point RGB ``[N, 3]``: the strands' own colours, else the preset's root-to-tip ramp with a
    per-strand brightness variation."""
    if strands.colors is not None:
        return np.clip(strands.colors.astype(np.float64), 0, 1)
    p = PRESETS[preset]
    counts = strands.point_counts
    owner = np.repeat(np.arange(strands.count), counts)
    start = np.repeat(strands.offsets[:-1], counts)
    t = (np.arange(len(owner)) - start) / np.maximum(np.repeat(counts, counts) - 1, 1)
    rng = np.random.default_rng(seed)
    scale = (1 + 0.25 * rng.standard_normal(strands.count)).clip(0.4, 1.8)[owner]
    rgb = np.asarray(p["root"])[None] * (1 - t[:, None]) + np.asarray(p["tip"])[None] * t[:, None]
    return np.clip(rgb * scale[:, None], 0, 1)


def multitone_colours(strands: Strands, tones: int, seed: int = 0) -> np.ndarray:
    """Per-point RGB ``[N, 3]`` of the multi-tone case: every strand in ``tones`` segments along its
    length with hard boundaries jittered per strand, each segment one palette tone."""
    from cghair_format.synth import melanin_rgb

    if not 2 <= tones <= len(MULTITONE_MELANIN):
        raise DatasetError(f"multi-tone needs 2 to {len(MULTITONE_MELANIN)} tones, got {tones}")
    counts = strands.point_counts
    owner = np.repeat(np.arange(strands.count), counts)
    start = np.repeat(strands.offsets[:-1], counts)
    t = (np.arange(len(owner)) - start) / np.maximum(np.repeat(counts, counts) - 1, 1)
    rng = np.random.default_rng(seed)
    bounds = (np.arange(1, tones) + MULTITONE_JITTER * rng.uniform(-1, 1, (strands.count, tones - 1))) / tones
    tone = (t[:, None] >= bounds[owner]).sum(1)
    scale = (1 + MULTITONE_BRIGHTNESS * rng.standard_normal(strands.count)).clip(0.6, 1.4)[owner]
    palette = melanin_rgb(*np.asarray(MULTITONE_MELANIN[:tones]).T)
    return np.clip(palette[tone] * scale[:, None], 0, 1)
