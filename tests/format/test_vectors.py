"""The conformance vectors in spec/vectors: valid files decode to their expected values, must-reject
files raise the named error."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format import errors
from cghair_format.geometry import strand_points

VECTORS = Path(__file__).resolve().parents[2] / "spec" / "vectors"
VALID = sorted(p for p in VECTORS.glob("*.cgh") if not p.name.startswith("reject_"))
REJECT = json.loads((VECTORS / "reject.json").read_text())


def test_vector_folder_is_complete():
    assert len(VALID) >= 5 and len(REJECT) >= 8
    assert any("point_counts" in np.load(p.with_name(p.stem + ".expected.npz")) for p in VALID)
    assert sorted(p.name for p in VECTORS.glob("reject_*.cgh")) == sorted(REJECT)


@pytest.mark.parametrize("path", VALID, ids=lambda p: p.stem)
def test_valid_vector_decodes_to_expected(path):
    expected = np.load(path.with_name(path.stem + ".expected.npz"))
    asset, g = cgh.read_with_gaussians(path)
    # the points are exact (spec 4, "Arithmetic"), placeholders included; the Gaussians' float32 maths may
    # round otherwise
    np.testing.assert_array_equal(strand_points(asset.cards, asset.strand_card, asset.uvd), expected["points"])
    counts = expected["point_counts"] if "point_counts" in expected else np.full(asset.n_strands,
                                                                                  asset.points_per_strand)
    np.testing.assert_array_equal(asset.counts, counts)
    strands = cgh.decode_strands(asset)
    np.testing.assert_array_equal(strands.point_counts, counts)
    real = np.arange(asset.points_per_strand)[None, :] < counts[:, None]
    np.testing.assert_array_equal(strands.points, expected["points"][real])
    assert g.count == int((counts - 1).sum())
    for name in ("means", "rotations", "scales", "opacities"):
        np.testing.assert_allclose(getattr(g, name), expected[name], rtol=0, atol=1e-6, err_msg=name)
    np.testing.assert_allclose(g.sh, expected["sh"], rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("name", sorted(REJECT))
def test_reject_vector_raises_named_error(name):
    spec = REJECT[name]
    for read in (cgh.read, cgh.read_with_gaussians):
        with pytest.raises(getattr(errors, spec["error"]), match=spec["message"]):
            read(VECTORS / name)


def test_worked_example_in_the_spec_matches_its_vector():
    from cghair_format import container

    spec = (VECTORS.parent / "cgh.md").read_text()
    data = (VECTORS / "minimal_compact.cgh").read_bytes()
    assert f"**{len(data)} bytes**" in spec
    _, infos = container.read_table(data)
    for info in infos:
        codec = "zstd" if info.codec else "raw"
        row = next((line for line in spec.splitlines() if f"| {info.type}, {codec}" in line), "")
        assert row.startswith(f"| {info.stored} (") and re.search(rf"at (offset )?{info.offset}\b", row), (info, row)
