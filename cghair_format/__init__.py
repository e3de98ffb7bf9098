"""CGHair's .cgh codec: the data model, reading and writing, and decoding to strands and Gaussians.

Importing this package needs only numpy and zstandard, and its compiled kernels (``_decoder``, ``_writer``, built
from Cython by ``pip install``, which needs a C compiler).
"""

try:
    from . import _decoder, _writer  # noqa: F401  (checked first, so that a missing build says what to do)
except ImportError as exc:  # pragma: no cover - only a source tree that was never built gets here
    raise ImportError("cghair_format's compiled kernels are not built: run `pip install -e .` in the repository "
                      "(it needs a C compiler: gcc, clang or MSVC), or `make venv`") from exc

from .asset import Appearance, Cards, HairAsset, MlpLayer
from .codec import (
    AnimationReader,
    EncodeReport,
    animation_reader,
    decode,
    encode,
    read,
    read_animation,
    read_info,
    read_with_gaussians,
    write,
)
from .errors import AssetError, CghError, CghFormatError, MissingDependencyError
from .gaussians import Gaussians, decode_gaussians, decode_points, decode_strands
from .profiles import PROFILES, Profile
from .strands import Strands

__all__ = [
    "PROFILES", "AnimationReader", "Appearance", "AssetError", "Cards", "CghError", "CghFormatError", "EncodeReport",
    "Gaussians", "HairAsset", "MissingDependencyError", "MlpLayer", "Profile", "Strands", "animation_reader", "decode",
    "decode_gaussians", "decode_points", "decode_strands", "encode", "read", "read_animation", "read_info",
    "read_with_gaussians", "write",
]
__version__ = "0.2.0"
