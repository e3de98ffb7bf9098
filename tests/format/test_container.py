"""The byte layer: header, chunk table, checksums, skipping and rejecting chunks."""

import pytest

from cghair_format import container
from cghair_format.errors import (
    BadMagicError,
    CghFormatError,
    ChecksumError,
    LimitError,
    TruncatedError,
    UnknownRequiredChunkError,
    UnsupportedVersionError,
)

KNOWN = {"AAAA", "BBBB"}


def _file(*chunks):
    return container.pack(list(chunks))


def test_round_trip_and_alignment():
    data = _file(container.Chunk("AAAA", b"x" * 1000), container.Chunk("BBBB", b"abc"))
    assert len(data) % container.ALIGN == 0
    _, infos, payloads = container.unpack(data, KNOWN)
    assert payloads == {"AAAA": b"x" * 1000, "BBBB": b"abc"}
    assert infos[0].codec == container.CODEC_ZSTD and infos[1].codec == container.CODEC_RAW
    assert all(i.offset % container.ALIGN == 0 for i in infos)


def test_unknown_optional_chunk_is_skipped_unknown_required_fails():
    data = _file(container.Chunk("AAAA", b"1"), container.Chunk("ZZZZ", b"2", required=False))
    assert container.unpack(data, KNOWN)[2] == {"AAAA": b"1"}
    data = _file(container.Chunk("AAAA", b"1"), container.Chunk("ZZZZ", b"2", required=True))
    with pytest.raises(UnknownRequiredChunkError, match="ZZZZ"):
        container.unpack(data, KNOWN)


def test_newer_minor_is_read_newer_major_is_rejected():
    data = _file(container.Chunk("AAAA", b"1"))
    assert container.unpack(container.rewrite_header(data, minor=7), KNOWN)[0] == (2, 7)
    assert container.unpack(container.rewrite_header(data, major=1), KNOWN)[0] == (1, 0)  # the codec decides
    with pytest.raises(UnsupportedVersionError, match="3.0"):
        container.unpack(container.rewrite_header(data, major=3, minor=0), KNOWN)


def test_bad_magic_truncation_and_lengths():
    data = _file(container.Chunk("AAAA", b"payload" * 10))
    with pytest.raises(BadMagicError):
        container.unpack(b"PK\x03\x04" + data[4:], KNOWN)
    with pytest.raises(TruncatedError):
        container.unpack(data[:20], KNOWN)
    with pytest.raises(TruncatedError):
        container.unpack(data[:-8], KNOWN)
    with pytest.raises(LimitError):
        container.unpack(container.rewrite_header(data, count=10_000), KNOWN)


def test_checksums_cover_table_and_payload():
    data = bytearray(_file(container.Chunk("AAAA", b"payload" * 10)))
    bad = bytearray(data)
    bad[-12] ^= 1
    with pytest.raises(ChecksumError, match="chunk 'AAAA'"):
        container.unpack(bytes(bad), KNOWN)
    bad = bytearray(data)
    bad[container.HEADER_SIZE + 10] ^= 1
    with pytest.raises(ChecksumError, match="header"):
        container.unpack(bytes(bad), KNOWN)


def test_nonzero_padding_is_rejected():
    data = bytearray(_file(container.Chunk("AAAA", b"abc")))  # 3 bytes of payload, 5 of padding
    data[-1] = 1
    with pytest.raises(CghFormatError, match="padding"):
        container.unpack(bytes(data), KNOWN)


def test_declared_expansion_is_bounded():
    with pytest.raises(LimitError):
        container.pack([container.Chunk("AAAA", b"")] * (container.MAX_CHUNKS + 1))
