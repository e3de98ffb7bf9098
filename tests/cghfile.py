"""Reading a written .cgh's META in tests: what the writer chose."""

from __future__ import annotations

import json

from cghair_format import codec, container


def quant_of(data: bytes) -> dict:
    """META ``quant`` of the encoded file ``data``: the quantization parameters the writer chose."""
    return json.loads(container.unpack(data, set(codec.KNOWN_CHUNKS))[2]["META"])["quant"]
