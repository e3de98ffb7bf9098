"""The hair card builder: any strands -> the card geometry and a default appearance of a .cgh.

Stages (one module each): :mod:`.cluster` (k-means of strands), :mod:`.guide` (smoothed centroid
spines), :mod:`.normals` (L1 card planes, widths), :mod:`.inverse` (exact ``(u, v, delta)`` of
every point), :mod:`.textures` (strand textures, card groups), :mod:`.appearance` (untrained
appearance). Needs the ``cards`` extra (scipy, scikit-learn); ``import cghair_format`` does not
import this package.
"""

from .build import CardBuild, CardBuildError, ReconstructionError, build_cards
from .debug import write_debug

__all__ = ["CardBuild", "CardBuildError", "ReconstructionError", "build_cards", "write_debug"]
