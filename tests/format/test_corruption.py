"""Corrupt files: every truncation and >= 10,000 random mutations raise CghFormatError within 1 s.

Every byte of a .cgh is covered: the header and chunk table by the header checksum, each chunk's
stored bytes by its own checksum, alignment padding by the must-be-zero rule, and the file length by
the header. So no single flipped byte can go unnoticed, and this sweep asserts exactly that. Files
re-sealed after their payloads were changed get past the checksums; the decoders must refuse those
(or decode them to a valid asset) on their own.
"""

import re
import time

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format.examples import example_asset

MAX_SECONDS = 1.0
pytestmark = pytest.mark.filterwarnings("error")  # refusing bad input must not warn


@pytest.fixture(scope="module")
def small_file() -> bytes:
    return cgh.encode(example_asset(11, strands=24, points=12, cards=4, segments=5), "compact")[0]


def _must_reject(data: bytes) -> None:
    start = time.perf_counter()
    with pytest.raises(cgh.CghFormatError):
        cgh.decode(data)
    assert time.perf_counter() - start < MAX_SECONDS


def test_every_truncation_is_rejected(small_file):
    for n in range(len(small_file)):
        _must_reject(small_file[:n])


def test_every_single_byte_flip_is_caught(small_file):
    for pos in range(len(small_file)):
        bad = bytearray(small_file)
        bad[pos] ^= 0xFF
        _must_reject(bytes(bad))


def test_ten_thousand_random_mutations(small_file):
    rng = np.random.default_rng(2026)
    kinds = {"flip": 0, "insert": 0, "delete": 0, "multi": 0}
    for i in range(10_000):
        bad = bytearray(small_file)
        kind = ("flip", "insert", "delete", "multi")[i % 4]
        pos = int(rng.integers(0, len(bad)))
        if kind == "flip":
            bad[pos] ^= int(rng.integers(1, 256))
        elif kind == "insert":
            bad[pos:pos] = rng.integers(0, 256, int(rng.integers(1, 9)), dtype=np.uint8).tobytes()
        elif kind == "delete":
            del bad[pos:pos + int(rng.integers(1, 9))]
        else:
            for p in rng.integers(0, len(bad), int(rng.integers(2, 6))):
                bad[p] = int(rng.integers(0, 256))
            if bytes(bad) == small_file:
                continue
        kinds[kind] += 1
        _must_reject(bytes(bad))
    assert sum(kinds.values()) >= 9_900


def test_mutated_files_never_return_an_asset_with_bad_values(small_file):
    """Even garbage that passes the checksum (re-checksummed by an attacker) fails cleanly."""
    from cghair_format import container

    rng = np.random.default_rng(7)
    _, infos, payloads = container.unpack(small_file, set(payloads_types := ("META", "CARD", "STRD", "OPAC",
                                                                              "LOGT", "CBKS", "MLPW")))
    for _ in range(300):
        name = payloads_types[int(rng.integers(1, len(payloads_types)))]
        body = bytearray(payloads[name])
        body[int(rng.integers(0, len(body)))] ^= int(rng.integers(1, 256))
        chunks = [container.Chunk(t, bytes(body) if t == name else payloads[t]) for t in payloads_types]
        data = container.pack(chunks)
        try:
            asset = cgh.decode(data)
        except cgh.CghFormatError:
            continue
        asset.validate()  # a flip that still decodes must give a consistent asset


@pytest.mark.parametrize("chunk", ["META", "CARD", "STRD", "OPAC", "LOGT", "CBKS", "MLPW"])
def test_resealed_garbage_is_refused_or_decodes(small_file, chunk):
    """Checksums catch accidents; a file re-sealed after a chunk's payload was changed (valid CRCs)
    reaches the decoders themselves (the rANS coder for STRD), which must answer with CghFormatError
    or a valid asset, fast, without a warning; and decoding straight to Gaussians the same."""
    from cghair_format import codec, container

    _, infos = container.read_table(small_file)
    payloads = container.unpack(small_file, set(codec.KNOWN_CHUNKS))[2]
    rng = np.random.default_rng(7)
    refused = 0
    for _ in range(150):
        body = bytearray(payloads[chunk])
        for _ in range(int(rng.integers(1, 4))):
            body[int(rng.integers(0, len(body)))] = int(rng.integers(0, 256))
        data = container.pack([container.Chunk(i.type, bytes(body) if i.type == chunk else payloads[i.type],
                                               i.required) for i in infos], level=1)
        start = time.perf_counter()
        try:
            cgh.decode(data).validate()
        except cgh.CghFormatError as exc:
            refused += 1
            with pytest.raises(type(exc), match=re.escape(str(exc))):
                cgh.read_with_gaussians(data)
        else:
            cgh.read_with_gaussians(data)
        assert time.perf_counter() - start < MAX_SECONDS
    if chunk in ("STRD", "META"):
        assert refused > 100  # most garbage there is caught by the decoder's own checks
