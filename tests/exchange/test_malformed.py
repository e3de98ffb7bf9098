"""Truncated and malformed files raise a CghError subclass that names the file."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from hairdata import REAL_FILES, hair_path

from cghair_format.errors import CghError
from cghair_format.exchange import StrandFileError, UnsupportedFormatError, load_strands, save_strands

CUTS = (0, 3, 64, 127, 0.25, 0.5, 0.9)
pytestmark = pytest.mark.filterwarnings("error")  # refusing bad input must not warn


def _cut_points(size: int) -> list[int]:
    cuts = {int(c * size) if isinstance(c, float) else c for c in CUTS}
    return sorted(c for c in cuts if c < size)


@pytest.mark.parametrize("name", sorted(REAL_FILES))
def test_truncated_real_files(name, tmp_path):
    data = hair_path(name).read_bytes()
    for cut in _cut_points(len(data)):
        path = tmp_path / f"cut{cut}_{name}"
        path.write_bytes(data[:cut])
        with pytest.raises(CghError) as info:
            load_strands(path)
        assert str(path) in str(info.value), f"cut at {cut}: message does not name the file: {info.value}"


@pytest.mark.parametrize("ext", [".hair", ".data", ".tfx", ".ply", ".npz", ".usda", ".usdc", ".cgh"])
def test_garbage_files(ext, tmp_path):
    rng = np.random.default_rng(1)
    for i, blob in enumerate([b"", b"\x00" * 200, rng.bytes(4096), b"garbage header\n" * 40]):
        path = tmp_path / f"g{i}{ext}"
        path.write_bytes(blob)
        with pytest.raises(CghError) as info:
            load_strands(path)
        assert str(path) in str(info.value)


def test_corrupted_counts(tmp_path, small_strands):
    # a .hair whose segment array disagrees with the declared point count
    path = tmp_path / "bad.hair"
    save_strands(small_strands, path)
    raw = bytearray(path.read_bytes())
    raw[8:12] = (999).to_bytes(4, "little")
    path.write_bytes(bytes(raw))
    with pytest.raises(StrandFileError, match="bad.hair.*declares 999"):
        load_strands(path)
    # a .data strand with a negative point count
    path = tmp_path / "bad.data"
    save_strands(small_strands, path)
    raw = bytearray(path.read_bytes())
    raw[4:8] = (-5).to_bytes(4, "little", signed=True)
    path.write_bytes(bytes(raw))
    with pytest.raises(StrandFileError, match="declares -5 points"):
        load_strands(path)


def test_unknown_extension_and_missing_file(tmp_path, small_strands):
    with pytest.raises(UnsupportedFormatError, match="known extensions"):
        load_strands(tmp_path / "x.obj")
    with pytest.raises(UnsupportedFormatError, match="cannot write"):
        save_strands(small_strands, tmp_path / "x.cgh")
    with pytest.raises(FileNotFoundError):
        load_strands(tmp_path / "absent.hair")


def test_trailing_bytes_in_data_file(tmp_path):
    src = hair_path("Bangs_100.data")
    path = tmp_path / "extra.data"
    shutil.copy(src, path)
    with open(path, "ab") as f:
        f.write(b"\x01\x02\x03")
    with pytest.raises(StrandFileError, match="unexpected bytes"):
        load_strands(path)
