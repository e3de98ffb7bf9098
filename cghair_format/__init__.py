"""CGHair's .cgh codec: the data model, reading and writing, and decoding to strands and Gaussians.

Importing this package needs only numpy and zstandard.
"""

from .asset import Appearance, Cards, HairAsset, MlpLayer
from .codec import EncodeReport, decode, encode, read, read_info, write
from .errors import AssetError, CghError, CghFormatError, MissingDependencyError
from .gaussians import Gaussians, decode_gaussians, decode_points
from .profiles import PROFILES, Profile
from .strands import Strands

__all__ = [
    "PROFILES", "Appearance", "AssetError", "Cards", "CghError", "CghFormatError", "EncodeReport", "Gaussians",
    "HairAsset", "MissingDependencyError", "MlpLayer", "Profile", "Strands", "decode", "decode_gaussians",
    "decode_points", "encode", "read", "read_info", "write",
]
__version__ = "0.1.0"
