"""Crafted and mutated strand files (issues 21, 35): every importer refuses them with a StrandFileError naming
the file (and the field at fault), checks sizes before it allocates (peak traced memory), takes under a
second and raises no warning on the way (the module runs with warnings as errors)."""

from __future__ import annotations

import io
import struct
import time
import tracemalloc
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest

from cghair_format.errors import CghError
from cghair_format.exchange import StrandFileError, load_strands, save_strands
from cghair_format.exchange.hair import HEADER as HAIR_HEADER
from cghair_format.limits import ReadLimits, set_default_limits

MAX_SECONDS = 1.0
MAX_TRACED = 64 << 20

pytestmark = pytest.mark.filterwarnings("error")


def _refused(path, match: str | None = None) -> StrandFileError:
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(StrandFileError, match=match) as info:
            load_strands(path)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - start < MAX_SECONDS
    assert peak < MAX_TRACED, peak
    assert str(path) in str(info.value)
    return info.value


def test_hair_header_cannot_allocate_beyond_the_file(tmp_path):
    """128 bytes declaring 2^30 strands of 2^32 - 1 points, without a segments array (the default
    segment count then applies to every strand): refused before the per-strand array is made."""
    path = tmp_path / "big.hair"
    path.write_bytes(HAIR_HEADER.pack(b"HAIR", 1 << 30, (1 << 32) - 1, 2, 3, 1.0, 1.0, 1, 1, 1, b""))
    _refused(path, "cannot hold")


def test_zero_point_strands_are_refused(tmp_path):
    path = tmp_path / "z.npz"
    np.savez(path, points=np.zeros((4, 3), np.float32), offsets=np.array([0, 2, 2, 4]))
    _refused(path, "1 strands have no points")


def test_usda_that_is_not_utf8(tmp_path):
    pytest.importorskip("pxr", reason="usd-core (the usd extra) reads USD")
    from pxr import Usd  # noqa: F401  (imported before the clock starts: its first import takes seconds)

    path = tmp_path / "latin1.usda"
    path.write_bytes(b'#usda 1.0\n(\n    doc = "caf\xe9"\n)\ndef BasisCurves "hair" {\n'
                     b'  int[] curveVertexCounts = [2]\n  point3f[] points = [(0,0,0),(1,1,1)]\n'
                     b'  uniform token type = "linear"\n}\n')
    _refused(path, "UTF-8")


def _npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def test_npz_whose_header_declares_a_huge_array(tmp_path):
    """An .npy header in the archive that declares 10^12 x 3 floats: refused before numpy allocates."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        head = io.BytesIO()
        np.lib.format.write_array_header_1_0(head, {"descr": "<f4", "fortran_order": False,
                                                    "shape": (10 ** 12, 3)})
        z.writestr("points.npy", head.getvalue() + bytes(64))
        z.writestr("offsets.npy", _npy(np.array([0, 1], np.int64)))
    path = tmp_path / "huge.npz"
    path.write_bytes(buf.getvalue())
    _refused(path, "declares")


def _member(name: str, stored: bytes, raw: int, crc: int, method: int) -> tuple[bytes, bytes]:
    """A zip member (its local header and ``stored`` bytes) and its central directory entry (local header
    offset 0: :func:`_zip` fills it in); ``method`` 0 stores, 8 deflates."""
    encoded = name.encode()
    fields = (method, 0, 0, crc, len(stored), raw, len(encoded), 0)
    local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, *fields) + encoded + stored
    central = struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, *fields, 0, 0, 0, 0, 0) + encoded
    return local, central


def _stored(name: str, data: bytes) -> tuple[bytes, bytes]:
    return _member(name, data, len(data), zlib.crc32(data), 0)


def _zeros_member(name: str, header: bytes, mib: int) -> tuple[bytes, bytes]:
    """A deflated member ``name`` holding ``header`` then zeros up to ``mib`` MiB, in about 1 KB per MiB.
    The deflate stream is written a block at a time (each MiB ends in a full flush, so every block after
    the first is the same bytes) instead of compressing a gigabyte; the CRC is left 0, as a reader must
    refuse the member before it inflates its data."""
    z = zlib.compressobj(9, zlib.DEFLATED, -15)
    first = z.compress(header + bytes((1 << 20) - len(header))) + z.flush(zlib.Z_FULL_FLUSH)
    block = z.compress(bytes(1 << 20)) + z.flush(zlib.Z_FULL_FLUSH)
    return _member(name, first + block * (mib - 1) + z.flush(), mib << 20, 0, 8)


def _zip(members: list[tuple[bytes, bytes]]) -> bytes:
    """A zip archive of members (each central entry's local header offset filled in)."""
    body, central = b"", b""
    for local, entry in members:
        central += entry[:42] + struct.pack("<I", len(body)) + entry[46:]
        body += local
    end = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, len(members), len(members), len(central), len(body), 0)
    return body + central + end


def _npy_header(shape: tuple, descr: str = "<f4") -> bytes:
    head = io.BytesIO()
    np.lib.format.write_array_header_1_0(head, {"descr": descr, "fortran_order": False, "shape": shape})
    return head.getvalue()


GIB_POINTS = ((1 << 30) // 12, 3)  # a gigabyte of float32 points: 89 million, beyond the 2^24 Gaussians limit


def _bomb_refused(path: Path, match: str) -> None:
    """Refused in under a second within a small multiple of the file's own size (traced)."""
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(StrandFileError, match=match):
            load_strands(path)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    seconds = time.perf_counter() - start
    assert seconds < MAX_SECONDS, seconds
    assert peak < 4 * path.stat().st_size, (peak, path.stat().st_size)


def test_npz_that_inflates_to_a_gigabyte_is_refused_before_inflating(tmp_path):
    """1 MB on disk, 1 GiB of points inflated (honestly declared by its .npy header and the zip's central
    directory): more points than the reader's Gaussian limit allows."""
    path = tmp_path / "bomb.npz"
    path.write_bytes(_zip([_zeros_member("points.npy", _npy_header(GIB_POINTS), 1024),
                           _stored("offsets.npy", _npy(np.array([0, GIB_POINTS[0]])))]))
    assert path.stat().st_size < 2 << 20
    _bomb_refused(path, "declares 268,435,455 values, more than the 50,331,649 that this reader's limit of "
                        "16,777,216 points allows")


def test_npz_beyond_the_decoded_bytes_limit_is_refused(tmp_path):
    path = tmp_path / "wide.npz"
    offsets = _npy(np.array([0, 1 << 20]))
    path.write_bytes(_zip([_zeros_member("points.npy", _npy_header((1 << 20, 3), "<f8"), 24),
                           _stored("offsets.npy", offsets)]))
    set_default_limits(ReadLimits(max_decoded_bytes=16 << 20))
    try:
        _bomb_refused(path, f"inflate to {(24 << 20) + len(offsets):,} bytes, more than this reader's limit of "
                            "16,777,216")
    finally:
        set_default_limits(ReadLimits())


def test_npz_members_it_does_not_read_are_not_inflated(tmp_path):
    """A gigabyte of zeros in a member the importer does not know is never inflated: the file loads fast."""
    path = tmp_path / "extra.npz"
    points = np.zeros((4, 3), np.float32)
    points[:, 1] = np.arange(4)
    path.write_bytes(_zip([_stored("points.npy", _npy(points)), _stored("offsets.npy", _npy(np.array([0, 2, 4]))),
                           _zeros_member("junk.npy", _npy_header(GIB_POINTS), 1024)]))
    start = time.perf_counter()
    assert load_strands(path).count == 2
    assert time.perf_counter() - start < MAX_SECONDS


def _npy(a: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, a)
    return out.getvalue()


@pytest.mark.parametrize("arrays, match", [
    ({"points": np.array([["a", "b", "c"]]), "offsets": np.array([0, 1])}, "not a real number type"),
    ({"points": np.zeros((2, 3), np.float32), "offsets": np.array([0, 2]), "meters_per_unit": np.ones(3)},
     "must hold one value"),
    ({"points": np.zeros((2, 3), np.float32), "offsets": np.array([0, 2]), "up_axis": np.str_("Y" * 100)},
     "not a short string"),
    ({"points": np.zeros((2, 3), np.float32), "offsets": np.array([0, 2]), "widths": np.ones((2, 2))}, "shape"),
    ({"points": np.zeros((2, 3), np.complex64), "offsets": np.array([0, 2])}, "not a real number type"),
])
def test_npz_with_arrays_of_the_wrong_kind(tmp_path, arrays, match):
    path = tmp_path / "bad.npz"
    path.write_bytes(_npz_bytes(**arrays))
    _refused(path, match)


def test_npz_with_a_corrupt_deflate_stream(tmp_path):
    data = bytearray(_npz_bytes(points=np.arange(3000, dtype=np.float32).reshape(-1, 3),
                                offsets=np.array([0, 1000])))
    start = data.index(b"points.npy") + len("points.npy")  # the member's compressed bytes follow its name
    for i in range(start + 8, start + 40):
        data[i] ^= 0x5A
    path = tmp_path / "zlib.npz"
    path.write_bytes(bytes(data))
    _refused(path)


def test_ply_comment_that_is_not_a_number(tmp_path):
    path = tmp_path / "c.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\ncomment points_per_strand abc\nelement vertex 2\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n")
    _refused(path, "points_per_strand abc")


EXTENSIONS = (".hair", ".data", ".tfx", ".ply", ".npz", ".usda")


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_mutated_files_raise_only_strand_file_errors(tmp_path, small_strands, ext):
    """300 seeded mutations (byte changes, cuts, insertions) of a valid file: each loads or is refused
    with a CghError naming the file, in under a second."""
    if ext == ".usda":
        pytest.importorskip("pxr", reason="usd-core (the usd extra) reads USD")
    if ext == ".tfx":
        from cghair_format.strands import resample

        small_strands = resample(small_strands, 8)
    path = tmp_path / f"base{ext}"
    save_strands(small_strands, path)
    base = path.read_bytes()
    rng = np.random.default_rng(21)
    for i in range(300):
        data = bytearray(base)
        pos = int(rng.integers(0, len(data)))
        kind = i % 3
        if kind == 0:
            for p in rng.integers(0, len(data), int(rng.integers(1, 5))):
                data[p] = int(rng.integers(0, 256))
        elif kind == 1:
            del data[pos:]
        else:
            data[pos:pos] = rng.integers(0, 256, int(rng.integers(1, 9)), dtype=np.uint8).tobytes()
        bad = tmp_path / f"m{i}{ext}"
        bad.write_bytes(bytes(data))
        start = time.perf_counter()
        try:
            load_strands(bad)
        except CghError as exc:
            assert str(bad) in str(exc), exc
        assert time.perf_counter() - start < MAX_SECONDS
        bad.unlink()


def _tfx3(points: np.ndarray, version: float = 3.0, positions_at: int = 304) -> bytes:
    """A TressFX 3 binary (TressFXFileObject: 296-byte header, positions offset at byte 144, float3)."""
    s, p = points.shape[:2]
    head = bytearray(296)
    struct.pack_into("<fIII", head, 0, version, s, p, 0)
    struct.pack_into("<I", head, 144, positions_at)
    return bytes(head) + bytes(max(positions_at - 296, 0)) + points.astype("<f4").tobytes()


def test_tressfx3_binary(tmp_path):
    rng = np.random.default_rng(3)
    points = np.cumsum(rng.normal(size=(5, 8, 3)), axis=1).astype(np.float32)
    path = tmp_path / "v3.tfx"
    path.write_bytes(_tfx3(points))
    strands = load_strands(path)
    assert strands.count == 5 and strands.up_axis == "Y"
    np.testing.assert_array_equal(strands.points, points.reshape(-1, 3))
    path.write_bytes(_tfx3(points)[:-4])
    _refused(path, "truncated")
    path.write_bytes(_tfx3(points, positions_at=200))
    _refused(path, "inside the 296-byte header")
