"""CGHair's .cgh codec: the data model, reading and writing, and decoding to strands and Gaussians.

Importing this package needs only numpy and zstandard.
"""

from .asset import Appearance, Cards, HairAsset, MlpLayer
from .errors import AssetError, CghError, CghFormatError, MissingDependencyError
from .gaussians import Gaussians, decode_gaussians, decode_points
from .strands import Strands

__all__ = [
    "Appearance", "AssetError", "Cards", "CghError", "CghFormatError", "Gaussians", "HairAsset",
    "MissingDependencyError", "MlpLayer", "Strands", "decode_gaussians", "decode_points",
]
__version__ = "0.1.0"
