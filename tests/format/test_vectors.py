"""The conformance vectors in spec/vectors: valid files decode to their expected values, which a second,
independent computation confirms; must-reject files raise the named error."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format import container, errors, reference_decoder
from cghair_format.geometry import strand_points
from cghair_format.streams import StreamReader

VECTORS = Path(__file__).resolve().parents[2] / "spec" / "vectors"
VALID = sorted(p for p in VECTORS.glob("*.cgh") if not p.name.startswith("reject_"))
REJECT = json.loads((VECTORS / "reject.json").read_text())


def test_vector_folder_is_complete():
    assert len(VALID) >= 5 and len(REJECT) >= 8
    assert any("point_counts" in np.load(p.with_name(p.stem + ".expected.npz")) for p in VALID)
    assert sorted(p.name for p in VECTORS.glob("reject_*.cgh")) == sorted(REJECT)
    assert {cgh.read_info(p)["profile"] for p in VALID if cgh.read_info(p)["animation"]} == {"compact", "lossless"}


@pytest.mark.slow
def test_generator_reproduces_the_committed_vectors(tmp_path):
    """`python spec/vectors/generate.py` writes every committed file again, byte for byte (the expected
    values array for array): vectors the writer can no longer make are stale, and this says which."""
    shutil.copy(VECTORS / "generate.py", tmp_path)  # it writes beside itself
    root = str(VECTORS.parents[1])
    env = os.environ | {"PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    subprocess.run([sys.executable, str(tmp_path / "generate.py")], check=True, env=env, cwd=root, timeout=300)
    written = sorted(p.name for p in tmp_path.iterdir() if p.name != "generate.py")
    assert written == sorted(p.name for p in VECTORS.iterdir() if p.name != "generate.py")
    stale = [name for name in written if not name.endswith(".npz")
             and (tmp_path / name).read_bytes() != (VECTORS / name).read_bytes()]
    assert not stale, f"regenerate the vectors (python spec/vectors/generate.py): {stale} differ"
    for name in (n for n in written if n.endswith(".npz")):
        fresh, kept = np.load(tmp_path / name), np.load(VECTORS / name)
        assert sorted(fresh.files) == sorted(kept.files), name
        assert all(np.array_equal(fresh[k], kept[k], equal_nan=True) for k in fresh.files), name


@pytest.mark.parametrize("path", VALID, ids=lambda p: p.stem)
def test_expected_values_agree_with_a_second_computation(path):
    """The expected values were written by the implementation (spec/vectors/generate.py): check them against
    computations that share none of its float code. Points and opacities from the reference decoder
    (written from the spec alone) or, in a lossless file, its card map on the stored floats; Gaussians from
    those points by spec 6.2 and SH by spec 6.3, in float64, here."""
    expected = np.load(path.with_name(path.stem + ".expected.npz"))
    points, counts, opacity = _reference(path)
    assert np.array_equal(points, expected["points"])
    asset = cgh.read(path)
    real = np.arange(points.shape[1] - 1)[None, :] < (counts - 1)[:, None]  # each strand's own segments
    means, rotations, scales = _spec_gaussians(points.astype(np.float64), real, asset.thickness)
    for name, value in (("means", means), ("rotations", rotations), ("scales", scales),
                        ("opacities", opacity[real])):
        np.testing.assert_allclose(expected[name], value, rtol=0, atol=1e-6, err_msg=name)
    np.testing.assert_allclose(expected["sh"], _spec_sh(asset)[real], rtol=1e-5, atol=1e-5)


def _reference(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``[S, P, 3]``, point counts and opacities ``[S, P-1]``: a quantized file's from the reference
    decoder and its H (spec 4.1, 4.4); a lossless file's from the reference card map (6.1) on the stored
    floats, and its stored opacities."""
    data = path.read_bytes()
    meta = json.loads(container.unpack(data, set(cgh.codec.KNOWN_CHUNKS), {"META"})[2]["META"])
    q = meta["quant"]
    if not q["lossless"]:
        ref = reference_decoder.decode_points(data)
        opac = StreamReader(container.unpack(data, set(cgh.codec.KNOWN_CHUNKS), {"OPAC"})[2]["OPAC"], "OPAC")
        rows = reference_decoder.hier_rows(opac, meta["strands"], meta["points"] - 1, q["base_stride"], "opacity")
        opacity = np.clip(np.array(rows) / q["opacity_scale"], 0, 1).astype(np.float32)
        return ref.points, ref.counts, opacity
    asset = cgh.read(path)
    c = asset.cards
    strips = [reference_decoder.strip(reference_decoder.Card(*(a.astype(np.float64).tolist() for a in (
        c.spine[k], c.normal[k], c.half_width[k]))), 0.0) for k in range(c.count)]
    points = np.array([[reference_decoder.card_map(strips[card], z.astype(np.float64).tolist()) for z in row]
                       for card, row in zip(asset.strand_card, asset.uvd, strict=True)]).astype(np.float32)
    return points, asset.counts, asset.opacity


def _spec_gaussians(x: np.ndarray, real: np.ndarray, d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Spec 6.2 for the real segments of points ``x [S, P, 3]``: means, (w, x, y, z) rotations taking +z
    onto each segment, standard deviations (d, d, length / 2)."""
    a, b = x[:, :-1][real], x[:, 1:][real]
    e = b - a
    length = np.linalg.norm(e, axis=1)
    direction = np.where(length[:, None] > 0, e / np.where(length > 0, length, 1)[:, None], [0.0, 0.0, 1.0])
    q = np.stack([1 + direction[:, 2], -direction[:, 1], direction[:, 0], np.zeros(len(e))], 1)
    q = np.where((1 + direction[:, 2] < 1e-12)[:, None], [0.0, 1.0, 0.0, 0.0], q)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    scales = np.stack([np.full(len(e), d), np.full(len(e), d), length / 2], 1)
    return (a + b) / 2, q, scales


def _spec_sh(asset) -> np.ndarray:
    """Spec 6.3 in float64: ``[S, P-1, NC, 3]`` SH of every segment, placeholders' included."""
    app = asset.appearance
    logits = app.logits.astype(np.float64)
    if app.weight_mode == "soft":
        z = np.exp(logits / app.temperature - (logits / app.temperature).max(1, keepdims=True))
        weights = z / z.sum(1, keepdims=True)
    else:
        weights = np.eye(app.k)[np.argmax(logits, axis=1)]
    group = asset.cards.group[asset.strand_card]
    h = np.einsum("sk,skd->sd", weights, app.codebooks.astype(np.float64)[group])
    for layer in app.mlp:
        h = h @ layer.weight.astype(np.float64).T + layer.bias.astype(np.float64)
        if layer.activation == "relu":
            h = np.maximum(h, 0)
    return h.reshape(asset.n_strands, asset.points_per_strand - 1, app.sh_coeffs, 3)


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
    clip = cgh.read_animation(path)
    assert (clip is None) == ("frame_spine" not in expected)
    if clip is not None:  # every frame's cards and points, exactly (spec 4.6, 6.1)
        np.testing.assert_array_equal(clip.spine, expected["frame_spine"])
        np.testing.assert_array_equal(clip.normal, expected["frame_normal"])
        for f in range(clip.frames):
            points = strand_points(clip.cards(asset.cards, f), asset.strand_card, asset.uvd)
            np.testing.assert_array_equal(points, expected["frame_points"][f])


ANIMATED = [p for p in VALID if cgh.read_info(p)["animation"] is not None]


@pytest.mark.parametrize("path", ANIMATED, ids=lambda p: p.stem)
def test_animated_vectors_agree_with_the_reference_decoder(path):
    """Each frame's cards as the reference decoder (spec 4.6 in plain Python, from the frame's block alone)
    decodes them, bit for bit, and the points on a few frames by its card map (6.1)."""
    expected = np.load(path.with_name(path.stem + ".expected.npz"))
    data = path.read_bytes()
    for f in range(len(expected["frame_spine"])):
        cards = reference_decoder.decode_frame(data, f)
        assert np.array([c.spine for c in cards], np.float32).tobytes() == expected["frame_spine"][f].tobytes()
        assert np.array([c.normal for c in cards], np.float32).tobytes() == expected["frame_normal"][f].tobytes()
    for f in (0, 33, len(expected["frame_spine"]) - 1):
        assert reference_decoder.frame_points(data, f).tobytes() == expected["frame_points"][f].tobytes()


@pytest.mark.parametrize("name", sorted(REJECT))
def test_reject_vector_raises_named_error(name):
    spec = REJECT[name]
    if spec.get("animation"):  # its rest pose is valid; a reader of its animation refuses it (spec 4.6)
        assert cgh.read(VECTORS / name).n_strands > 0
        readers = (cgh.read_animation,)
    else:
        readers = (cgh.read, cgh.read_with_gaussians)
    for read in readers:
        with pytest.raises(getattr(errors, spec["error"]), match=spec["message"]):
            read(VECTORS / name)


def test_worked_example_in_the_spec_matches_its_vector():
    spec = (VECTORS.parent / "cgh.md").read_text()
    data = (VECTORS / "minimal_compact.cgh").read_bytes()
    assert f"**{len(data)} bytes**" in spec
    _, infos = container.read_table(data)
    for info in infos:
        codec = "zstd" if info.codec else "raw"
        row = next((line for line in spec.splitlines() if f"| {info.type}, {codec}" in line), "")
        assert row.startswith(f"| {info.stored} (") and re.search(rf"at (offset )?{info.offset}\b", row), (info, row)
