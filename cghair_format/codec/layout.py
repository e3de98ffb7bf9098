"""What the reader and the writer share about a file's chunks (spec: "Chunks"): their names, the
interpolated strands' family (spec 4.5) and, from META, the strand coder's plan and scales."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..strand_coder import Prediction

REQUIRED_CHUNKS = ("META", "CARD", "STRD", "OPAC", "LOGT", "CBKS", "MLPW")
OPTIONAL_CHUNKS = ("SIDS", "ROOT", "SCOL", "XMET")
FAMILY_CHUNK = "CHLD"  # required where META quant.children > 0 (spec 4.5), absent otherwise
COUNTS_CHUNK = "PCNT"  # required where some strand has fewer than META points (spec 3), absent otherwise
ANIM_CHUNK = "ANIM"  # optional: the animation (spec 4.6), present exactly when META has ``animation``
ASSET_CHUNKS = frozenset(REQUIRED_CHUNKS + OPTIONAL_CHUNKS + (FAMILY_CHUNK, COUNTS_CHUNK))  # the rest pose's
KNOWN_CHUNKS = ASSET_CHUNKS | {ANIM_CHUNK}


class Family(NamedTuple):
    """The file's interpolated strands (spec 4.5): the first ``guides`` strands are coded in STRD, the
    rest are children of ``parents`` (indices among the guides) with ``weights``."""

    guides: int
    parents: np.ndarray  # [children, 3] int64
    weights: np.ndarray  # [children, 3] int64, summing to WEIGHT_ONE
    respaced: np.ndarray  # [children] bool: the blend resampled at even arc length


def prediction(q: dict) -> Prediction:
    """The strand coder's plan that META's ``quant`` states (spec 4.3)."""
    return Prediction(q["base_stride"], tuple(q["base_order"]), q["newton_steps"], tuple(q["level_taps"]),
                      q["newton_halvings"], float(q["stretch_max"]), q["base_guide"], bool(q["level_guide"]))


def uvd_scale(su: np.ndarray, sv: np.ndarray, strand_card: np.ndarray, step: float) -> np.ndarray:
    """Per strand, the factors ``[S, 3]`` that turn ``(u, v, delta)`` into quantization steps."""
    return np.stack([su[strand_card], sv[strand_card], np.ones(len(strand_card))], axis=-1) / step
