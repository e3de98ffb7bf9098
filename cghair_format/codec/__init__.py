"""HairAsset <-> .cgh bytes (spec: "Chunks"): quantized streams per profile, verified on write.

``write``/``read`` are the public entry points; ``encode``/``decode`` work on bytes. The modules, by
what they do:

- :mod:`.schema`: META's fields, types and ranges, one table that the reader checks and the writer
  writes from;
- :mod:`.reader`: bytes -> asset, every refusal a ``CghFormatError`` naming chunk and byte offset;
- :mod:`.layout`: what reader and writer share (chunk names, the interpolated strands' family);
- :mod:`.writer`: asset -> bytes, the step search that meets the profile's bound and the strands' order;
- :mod:`.choices`: the writer's per-file choices for the strand coder, each a search on a sample;
- :mod:`.chunks`: the chunk writer, settled streams -> chunk payloads;
- :mod:`.animation`: the animation part (ANIM), frames of card strips <-> keyframe blocks.
"""

from .animation import AnimationReader, AnimationReport
from .layout import FAMILY_CHUNK, KNOWN_CHUNKS, OPTIONAL_CHUNKS, REQUIRED_CHUNKS
from .reader import animation_reader, decode, read, read_animation, read_info, read_with_gaussians
from .writer import EncodeOptions, EncodeReport, OpacityMarks, encode, write

__all__ = ["FAMILY_CHUNK", "KNOWN_CHUNKS", "OPTIONAL_CHUNKS", "REQUIRED_CHUNKS", "AnimationReader", "AnimationReport",
           "EncodeOptions", "EncodeReport", "OpacityMarks", "animation_reader", "decode", "encode", "read",
           "read_animation", "read_info", "read_with_gaussians", "write"]
