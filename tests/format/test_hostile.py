"""Crafted hostile files (tests/hostile.py, issue 21): each is refused with a CghFormatError that names
a chunk and a byte offset, within 1 s and 256 MB above the process's resident memory; reader limits."""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hostile import reseal, small_file

import cghair_format as cgh
from cghair_format import container
from cghair_format.cli import main as cli_main
from cghair_format.limits import ReadLimits, decoded_bytes

MAX_SECONDS = 1.0
MAX_PEAK = 256 << 20
pytestmark = pytest.mark.filterwarnings("error")  # refusing bad input must not warn


@pytest.fixture(scope="module")
def outcomes() -> list[dict]:
    """Every case of tests/hostile.py, decoded in a fresh process (so that its peak memory is its own)."""
    tests = Path(__file__).resolve().parents[1]
    path = os.pathsep.join([str(tests.parent), str(tests), os.environ.get("PYTHONPATH", "")])
    env = dict(os.environ, PYTHONPATH=path)
    run = subprocess.run([sys.executable, str(tests / "hostile.py")], capture_output=True, text=True, env=env,
                         timeout=300, check=True)
    return [json.loads(line) for line in run.stdout.splitlines()]


def test_every_crafted_file_is_refused_where_it_is_wrong(outcomes):
    assert len(outcomes) >= 20
    for case in outcomes:
        kind, chunk, offset, _ = case["outcome"].split("|", 3)
        assert kind.endswith("Error") and not kind.startswith("ESCAPE"), case
        assert chunk != "None" and offset != "None", case


def test_refusals_are_fast_and_small(outcomes):
    for case in outcomes:
        assert case["seconds"] < MAX_SECONDS, case
        assert case["peak"] < MAX_PEAK, case


def test_a_file_within_the_limits_decodes():
    data = small_file()
    asset = cgh.decode(data, ReadLimits(max_gaussians=264))
    assert asset.n_gaussians == 264
    _, infos = container.read_table(data)
    meta = json.loads(container.unpack(data, set(cgh.codec.KNOWN_CHUNKS), {"META"})[2]["META"])
    need = decoded_bytes(meta, gaussians=False) + sum(i.raw for i in infos)
    cgh.decode(data, ReadLimits(max_decoded_bytes=need))
    with pytest.raises(cgh.CghFormatError, match="max-decoded-mb"):
        cgh.decode(data, ReadLimits(max_decoded_bytes=need - 1))
    with pytest.raises(cgh.CghFormatError, match="max-gaussians"):
        cgh.read(data, ReadLimits(max_gaussians=263))


def _array_bytes(obj) -> int:
    """The bytes of every numpy array in ``obj``, its dataclass fields and lists, counted one by one."""
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if dataclasses.is_dataclass(obj):
        return sum(_array_bytes(getattr(obj, f.name)) for f in dataclasses.fields(obj))
    if isinstance(obj, (list, tuple)):
        return sum(_array_bytes(x) for x in obj)
    return 0


@pytest.mark.parametrize("profile", ["compact", "high", "lossless"])
def test_the_limit_counts_what_the_decoder_returns(profile):
    """decoded_bytes (what the limits compare) against the arrays a decode really returns, measured: an
    undercount would let a file past --max-decoded-mb; the limit tests above take decoded_bytes on trust."""
    data = small_file(profile)
    meta = json.loads(container.unpack(data, set(cgh.codec.KNOWN_CHUNKS), {"META"})[2]["META"])
    asset, gaussians = cgh.read_with_gaussians(data)
    assert _array_bytes(asset) == decoded_bytes(meta, gaussians=False)
    assert _array_bytes(asset) + _array_bytes(gaussians) == decoded_bytes(meta, gaussians=True)


def test_the_cli_raises_the_limits(tmp_path, capsys):
    path = tmp_path / "a.cgh"
    path.write_bytes(small_file())
    assert cli_main(["--max-gaussians", "100", "validate", str(path)]) == 1
    assert "cgh --max-gaussians N" in capsys.readouterr().err
    assert cli_main(["--max-gaussians", "264", "validate", str(path)]) == 0
    assert cli_main(["--max-decoded-mb", "1", "validate", str(path)]) == 0
    assert cli_main(["validate", str(path)]) == 0  # the defaults are back for a later command


def test_every_flipped_byte_is_caught_in_every_chunk_known_or_not():
    """Optional chunks, known (SIDS, ROOT, SCOL, XMET) and unknown (XTRA, skipped), are checksummed like
    the others: a flip anywhere in the file is refused, whether or not the reader decodes that chunk."""
    from cghair_format.examples import example_asset

    asset = example_asset(11, strands=24, points=12, cards=4, segments=5)
    asset.strand_ids = np.arange(24, dtype=np.uint32)
    asset.root_uv = np.zeros((24, 2), np.float32)
    asset.metadata = {"source": "test"}
    data = reseal(cgh.encode(asset, "compact")[0],
                  extra=[container.Chunk("XTRA", bytes(range(200)), required=False)])
    types = {i.type for i in container.read_table(data)[1]}
    assert {"SIDS", "ROOT", "XMET", "XTRA"} <= types
    for pos in range(len(data)):
        bad = bytearray(data)
        bad[pos] ^= 0x01
        with pytest.raises(cgh.CghFormatError) as refused:
            cgh.decode(bytes(bad))
        assert refused.value.offset is not None, refused.value
        if pos % 7 == 0:  # cgh info reads META only, and checks every chunk all the same
            with pytest.raises(cgh.CghFormatError):
                cgh.read_info(bytes(bad))


def test_the_writer_refuses_non_finite_and_huge_values():
    from cghair_format.examples import example_asset

    for change in ("thickness", "spine", "metadata"):
        asset = example_asset(11, strands=24, points=12, cards=4, segments=5)
        if change == "thickness":
            asset.thickness = 1e308
        elif change == "spine":
            asset.cards.spine[0, 0, 0] = 3e38
        else:
            asset.metadata = {"x": float("nan")}
        with pytest.raises(cgh.AssetError):
            cgh.encode(asset, "lossless")
