"""HairAsset <-> .cgh: round trips within each profile's bound, sources, atomic writes."""

import dataclasses
import io
import mmap
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from cghfile import quant_of
from hypothesis import given, settings
from hypothesis import strategies as st

import cghair_format as cgh
from cghair_format import memory
from cghair_format.codec import writer
from cghair_format.errors import AssetError
from cghair_format.examples import example_asset, with_interpolated_strands
from cghair_format.gaussians import run_mlp, strand_latents, strand_weights
from cghair_format.quantize import weight_steps


def _diag(points):
    flat = points.reshape(-1, 3)
    return float(np.linalg.norm(flat.max(0) - flat.min(0)))


def _check_bounds(a, b, profile):
    prof = cgh.PROFILES[profile]
    pa, pb = cgh.decode_points(a), cgh.decode_points(b)
    if prof.lossless:
        for x, y in ((a.uvd, b.uvd), (a.opacity, b.opacity), (a.appearance.logits, b.appearance.logits),
                     (a.appearance.codebooks, b.appearance.codebooks), (a.cards.spine, b.cards.spine)):
            assert np.array_equal(x.astype(np.float32), y)
        for la, lb in zip(a.appearance.mlp, b.appearance.mlp, strict=True):
            assert np.array_equal(la.weight, lb.weight) and np.array_equal(la.bias, lb.bias)
        return
    assert np.linalg.norm(pa - pb, axis=-1).max() <= prof.position_tolerance * _diag(pa)
    assert np.abs(a.opacity - b.opacity).max() <= prof.opacity_tolerance + 1e-7
    assert np.array_equal(a.strand_card, b.strand_card) and np.array_equal(a.cards.group, b.cards.group)
    # codebooks and MLP: within half a step of a fraction of each array's RMS; the last layer's, stored in
    # the colour basis, within 0.85 of its step (biases a sixteenth of that)
    steps = weight_steps(a.appearance.codebooks, [(x.weight, x.bias) for x in a.appearance.mlp], prof.weight_step,
                         prof.mlp_fraction)
    assert np.abs(b.appearance.codebooks - a.appearance.codebooks).max() <= steps[0] / 2 * (1 + 1e-6)
    for j, (la, lb, step) in enumerate(zip(a.appearance.mlp, b.appearance.mlp, steps[1:], strict=True)):
        reach = 0.85 if j == len(steps) - 2 else 0.5
        assert np.abs(lb.weight - la.weight).max() <= reach * step * (1 + 1e-6) + 1e-6
        assert np.abs(lb.bias - la.bias).max() <= reach * step / 16 * (1 + 1e-6) + 1e-6
    # soft weights: stored as exp((logit - max) / tau) in 1/levels; each weight within K / (2 levels),
    # plus what the floor gives an entry stored as 0
    wa, wb = strand_weights(a.appearance), strand_weights(b.appearance)
    k_, tau = a.appearance.k, a.appearance.temperature
    assert np.abs(wa - wb).max() <= k_ / (2 * prof.logit_levels) + k_ * np.exp(prof.logit_floor / tau) + 1e-6


@pytest.mark.parametrize("profile", ["compact", "high"])
def test_writer_steps_follow_the_profile(profile):
    """META's weight steps are the profile's fractions of each array's RMS: compact stores the MLP on
    coarser steps than the codebooks (0.7 and 0.35 RMS), high both on 0.02."""
    prof, asset = cgh.PROFILES[profile], example_asset(1)
    app = asset.appearance
    written = cgh.read_info(cgh.encode(asset, profile)[0])["quant"]["weight_steps"]
    assert written == weight_steps(app.codebooks, [(x.weight, x.bias) for x in app.mlp], prof.weight_step,
                                   prof.mlp_fraction)
    assert (prof.mlp_fraction, prof.weight_step) == ((0.7, 0.35) if profile == "compact" else (0.02, 0.02))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10**6), strands=st.integers(1, 40), points=st.integers(2, 40),
       cards=st.integers(1, 6), segments=st.integers(1, 12), groups=st.integers(1, 3), k=st.integers(1, 5),
       sh=st.integers(0, 3), mode=st.sampled_from(["soft", "hard"]),
       profile=st.sampled_from(["lossless", "high", "compact"]))
def test_round_trip_within_profile_bounds(seed, strands, points, cards, segments, groups, k, sh, mode, profile):
    a = example_asset(seed, strands, points, cards, segments, groups, k, latent_dim=5, hidden=7, sh_degree=sh,
                      weight_mode=mode)
    data, report = cgh.encode(a, profile)
    b = cgh.decode(data)
    assert (report.strand_order is None) == cgh.PROFILES[profile].lossless
    a = report.in_file_order(a)
    _check_bounds(a, b, profile)
    assert report.max_point_error <= cgh.PROFILES[profile].position_tolerance * report.bbox_diagonal
    if mode == "hard":
        assert np.array_equal(np.argmax(a.appearance.logits, 1), np.argmax(b.appearance.logits, 1))


@pytest.mark.parametrize("profile", ["compact", "high", "lossless"])
def test_negligible_opacities_are_stored_at_most_as_opaque_and_code_smaller(profile):
    """Marked segments follow the input's strands through the writer's reordering, decode between 0
    and their own opacity (plus the profile's bound), the rest within the bound; lossless keeps all.
    The report gives the figures, and META records how many lie below the bound, with the budget."""
    a = example_asset(3, 60, 24, 4, 8, 2, 3, latent_dim=5, hidden=7)
    rng = np.random.default_rng(0)
    a.opacity = rng.uniform(0, 1, a.opacity.shape).astype(np.float32)
    negligible = rng.random(a.opacity.shape) < 0.8
    data, report = cgh.encode(a, profile, negligible=negligible, opacity_budget=0.1)
    plain_data, plain_report = cgh.encode(a, profile)
    b, plain = cgh.decode(data), cgh.decode(plain_data)
    order = np.arange(a.n_strands) if report.strand_order is None else report.strand_order
    own, marked = a.opacity[order], negligible[order]
    bound = cgh.PROFILES[profile].opacity_tolerance if not cgh.PROFILES[profile].lossless else 0
    assert (np.abs(b.opacity - own)[~marked] <= bound + 1e-7).all()
    assert (b.opacity[marked] >= 0).all() and (b.opacity[marked] <= own[marked] + bound + 1e-7).all()
    sizes = report.chunk_sizes["OPAC"], plain_report.chunk_sizes["OPAC"]
    marks, info = report.opacity, cgh.read_info(data)
    assert plain_report.opacity is None and marks.marked == np.count_nonzero(negligible) and marks.budget == 0.1
    assert marks.plain_bytes == sizes[1]
    if profile == "lossless":
        assert np.array_equal(b.opacity, plain.opacity) and sizes[0] == sizes[1]
        assert not marks.kept and marks.marked_bytes is None and info["opacities"]["lowered"] is None
        return
    below = b.opacity < own - bound
    assert sizes[0] < 0.7 * sizes[1] and below[marked].mean() > 0.3 and not below[~marked].any()
    assert marks.kept and marks.marked_bytes == sizes[0]
    assert np.count_nonzero(b.opacity < own - bound - 1e-6) <= marks.lowered <= np.count_nonzero(below)
    assert info["opacities"] == {"within": bound, "lowered": marks.lowered, "budget": 0.1}
    assert cgh.read_info(plain_data)["opacities"] == {"within": bound, "lowered": None, "budget": None}
    with pytest.raises(ValueError, match="negligible must be a bool array"):
        cgh.encode(a, profile, negligible=negligible[:, 1:])
    with pytest.raises(ValueError, match="opacity_budget is the share"):
        cgh.encode(a, profile, opacity_budget=0.1)


def test_marks_that_do_not_pay_leave_the_file_as_without_them():
    """Smooth opacities (a barely trained file's) code smaller as they are: the writer keeps the plain
    OPAC, so the file is byte for byte the one without marks, with no record of lowered opacities."""
    a = example_asset(3, 60, 24, 4, 8, 2, 3, latent_dim=5, hidden=7)
    a.opacity = np.tile(np.linspace(0.9, 0.3, a.opacity.shape[1]), (a.n_strands, 1)).astype(np.float32)
    negligible = np.random.default_rng(0).random(a.opacity.shape) < 0.3
    data, report = cgh.encode(a, "compact", negligible=negligible, opacity_budget=0.1)
    assert data == cgh.encode(a, "compact")[0]
    marks = report.opacity
    assert not marks.kept and marks.marked_bytes > marks.plain_bytes == report.chunk_sizes["OPAC"]
    assert "kept the plain stream" in marks.summary()
    assert "opacity_lowered" not in cgh.read_info(data)["quant"] and cgh.read_info(data)["opacities"]["lowered"] is None


def test_gaussians_decode_shapes_and_values():
    a = example_asset(3, sh_degree=2)
    g = cgh.decode_gaussians(a)
    n = a.n_gaussians
    assert g.means.shape == (n, 3) and g.rotations.shape == (n, 4) and g.sh.shape == (n, 9, 3)
    pts = cgh.decode_points(a)
    seg = pts[:, 1:] - pts[:, :-1]
    assert np.allclose(g.means, ((pts[:, 1:] + pts[:, :-1]) / 2).reshape(-1, 3), atol=1e-6)
    assert np.allclose(g.scales[:, 2], np.linalg.norm(seg, axis=-1).reshape(-1) / 2, atol=1e-6)
    # the rotation takes +z onto the segment direction
    w, x, y, z = g.rotations.T
    zaxis = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], -1)
    d = seg.reshape(-1, 3) / np.linalg.norm(seg.reshape(-1, 3), axis=1, keepdims=True)
    assert np.allclose(zaxis, d, atol=1e-5)


def test_latents_and_mlp_follow_the_spec_and_large_outputs_live_in_their_own_mapping(monkeypatch):
    a = example_asset(3, sh_degree=3)
    app = a.appearance
    group = a.cards.group[a.strand_card]
    latents = strand_latents(app, group)  # each strand's weights over its group's codebook
    np.testing.assert_allclose(latents, np.einsum("sk,skd->sd", strand_weights(app), app.codebooks[group]),
                               rtol=1e-6, atol=1e-6)
    small = run_mlp(app, latents)
    monkeypatch.setattr(memory, "LARGE_BYTES", 1)  # every layer's output from memory.empty's mapping
    mapped = run_mlp(app, latents)
    assert isinstance(mapped.base.base, memoryview) and isinstance(mapped.base.base.obj, mmap.mmap)
    assert mapped.flags.writeable and mapped.dtype == np.float32
    assert np.array_equal(mapped, small)
    h = latents  # spec 6.3, in float64: each layer W h + b, then its activation
    for layer in app.mlp:
        h = h @ layer.weight.astype(np.float64).T + layer.bias
        h = np.maximum(h, 0) if layer.activation == "relu" else h
    np.testing.assert_allclose(small, h, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("profile, children", [("lossless", False), ("high", False), ("compact", False),
                                               ("compact", True)])
def test_read_with_gaussians_gives_what_read_and_decode_gaussians_give(profile, children, monkeypatch):
    asset = example_asset(5, sh_degree=3)
    data = cgh.encode(with_interpolated_strands(asset, seed=1) if children else asset, profile)[0]
    assert (cgh.read_info(data)["quant"].get("children", 0) > 0) == children
    monkeypatch.setattr(memory, "LARGE_BYTES", 1)  # the SH faulted in ahead, in their own mapping
    got_asset, got = cgh.read_with_gaussians(io.BytesIO(data))
    want_asset = cgh.read(data)
    want = cgh.decode_gaussians(want_asset)
    for name in ("means", "rotations", "scales", "opacities", "sh"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert np.array_equal(got_asset.uvd, want_asset.uvd)
    assert np.array_equal(got_asset.appearance.logits, want_asset.appearance.logits)


@pytest.mark.parametrize("works", [True, False])
def test_large_arrays_are_faulted_in_by_chunks_or_else_at_once(works, monkeypatch):
    calls = []

    def madvise(address, length, advice):
        calls.append((length, advice))
        return 0 if works else -1

    monkeypatch.setattr(memory, "_MADVISE", madvise)
    monkeypatch.setattr(memory, "LARGE_BYTES", 1)
    a = memory.empty((5, memory.POPULATE_CHUNK // 8 + 1), np.float32)  # 2.5 chunks
    a[:] = 1.5
    assert a.sum() == 1.5 * a.size and isinstance(a.base.base, memoryview)
    if works:
        chunk, advice = memory.POPULATE_CHUNK, memory.MADV_POPULATE_WRITE
        assert calls == [(chunk, advice)] * 2 + [(a.nbytes - 2 * chunk, advice)]
    else:  # a kernel before 5.14: MAP_POPULATE, after one try
        assert len(calls) == 1


def test_encoding_turns_numpys_huge_pages_off_and_back_for_every_thread(monkeypatch):
    state = {"on": True}
    calls = []

    def switch(on):
        calls.append(on)
        was, state["on"] = state["on"], on
        return was

    monkeypatch.setattr(memory, "_set_madvise_hugepage", switch)
    seen = []
    encode = writer._encode
    monkeypatch.setattr(writer, "_encode", lambda *a: (seen.append(state["on"]), encode(*a))[1])
    asset = example_asset(2)
    cgh.encode(asset, "compact")
    assert seen == [False] and state["on"] is True and calls == [False, True]
    calls.clear()
    with memory.without_huge_pages():
        assert state["on"] is False
        with ThreadPoolExecutor(2) as pool:  # concurrent encodes: the last to finish turns them back on
            list(pool.map(lambda p: cgh.encode(asset, p), ["high", "compact", "lossless"]))
        assert state["on"] is False
    assert state["on"] is True and calls == [False, True]
    state["on"] = False  # a user's own setting (NUMPY_MADVISE_HUGEPAGE=0) is kept
    cgh.encode(asset, "compact")
    assert state["on"] is False


def test_numpy_has_the_huge_page_switch():
    assert memory._set_madvise_hugepage is not None  # numpy 1.20 to 2.x; without it, encoding just keeps them


@pytest.mark.skipif(memory._MADVISE is None, reason="Linux only")
def test_libc_madvise_populates_a_mapping():
    m = mmap.mmap(-1, 3 * mmap.PAGESIZE, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    assert memory._populate_by_chunks(m, len(m))  # Linux 5.14+: this project's machines have 6.x
    m.close()  # no view of it is left behind


@pytest.mark.parametrize("profile", ["high", "compact"])
def test_the_writer_writes_the_same_bytes_every_time(profile):
    """Its trial codings run two at a time on threads, and the appearance chunks are compressed on
    another while STRD is coded: the file must not depend on which finishes first."""
    asset = example_asset(4, strands=60, points=20, cards=5)
    first = cgh.encode(asset, profile)[0]
    assert all(cgh.encode(asset, profile)[0] == first for _ in range(4))


def test_sources_path_bytes_and_file_objects(tmp_path):
    a = example_asset(5)
    path = tmp_path / "a.cgh"
    cgh.write(a, path, "lossless")
    raw = path.read_bytes()
    for source in (path, str(path), raw, bytearray(raw), memoryview(raw), io.BytesIO(raw)):
        assert np.array_equal(cgh.read(source).uvd, a.uvd)


def test_optional_chunks_round_trip_and_are_skippable():
    a = example_asset(6, strands=10, points=5)
    a.strand_ids = np.arange(100, 110, dtype=np.uint32)
    a.root_uv = np.random.default_rng(0).random((10, 2)).astype(np.float32)
    a.source_color = np.random.default_rng(1).random((10, 5, 3)).astype(np.float32)
    a.metadata = {"training": {"iters": 3}}
    data, report = cgh.encode(a, "compact")
    b, a = cgh.decode(data), report.in_file_order(a)  # the optional per-strand data travel with their strands
    assert np.array_equal(b.strand_ids, a.strand_ids) and np.array_equal(b.root_uv, a.root_uv)
    assert np.abs(b.source_color - a.source_color).max() <= 0.5 / 255 + 1e-7
    assert b.metadata == a.metadata
    info = cgh.read_info(cgh.encode(a, "compact")[0])
    assert {c["type"]: c["required"] for c in info["chunks"]}["SCOL"] is False


def test_invalid_asset_is_refused_before_writing(tmp_path):
    a = example_asset(7)
    a.opacity[0, 0] = 2.0
    with pytest.raises(AssetError, match="opacity"):
        cgh.write(a, tmp_path / "x.cgh")
    assert not (tmp_path / "x.cgh").exists()


def test_interrupted_write_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "keep.cgh"
    cgh.write(example_asset(8), path)
    before = path.read_bytes()

    def boom(*_):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError, match="disk full"):
        cgh.write(example_asset(9), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["keep.cgh"]  # no temporary file left behind


def test_info_reports_counts_and_bits():
    a = example_asset(10)
    data, _ = cgh.encode(a)
    info = cgh.read_info(data)
    assert info["strands"] == a.n_strands and info["gaussians"] == a.n_gaussians
    assert info["bits_per_gaussian"] == pytest.approx(8 * len(data) / a.n_gaussians)
    assert sum(c["stored_bytes"] for c in info["chunks"]) < len(data)


@pytest.mark.parametrize("profile", ["compact", "high"])
def test_points_are_coded_on_the_quantized_cards_so_their_error_does_not_add(profile):
    """Points far off their card magnify every normal error (2 units off, the hair is 0.3 units tall):
    the writer codes their coordinates on the cards as quantized, so a few normal bits (the profile's,
    or enough to keep a step in u from moving such points far more than the strip) and a card step 1-4x
    the point step (4x, halved while some point has no coordinates near it on the cards: the normals
    turn with the quantized spine's tangents, which these points magnify too) still meet the point
    bound."""
    a = example_asset(12)
    a.uvd[..., 2] *= 400
    data, report = cgh.encode(a, profile)
    quant = quant_of(data)
    assert cgh.PROFILES[profile].normal_bits <= quant["normal_bits"] <= 12
    assert quant["card_step"] in (quant["step"], 2 * quant["step"], 4 * quant["step"])
    bound = cgh.PROFILES[profile].position_tolerance * report.bbox_diagonal
    b, a = cgh.decode(data), report.in_file_order(a)
    expected = cgh.decode_points(a)
    assert np.linalg.norm(cgh.decode_points(b) - expected, axis=-1).max() <= bound
    # the input's own card coordinates on the quantized cards would miss the bound
    on_quantized = cgh.decode_points(dataclasses.replace(a, cards=b.cards))
    assert np.linalg.norm(on_quantized - expected, axis=-1).max() > 2 * bound


def test_cards_too_coarse_to_hold_every_point_get_a_finer_card_step(monkeypatch):
    """A card step so coarse that narrow cards lose their width leaves points with no coordinates
    near them: the writer halves the card step until every point has them, and meets the bound."""
    a = example_asset(7)
    monkeypatch.setattr(writer, "CARD_STEP_FRACTION", 4096)
    data, report = cgh.encode(a, "compact")
    quant = quant_of(data)
    assert quant["card_step"] < 4096 * quant["step"]
    decoded = cgh.decode_points(cgh.decode(data))
    a = report.in_file_order(a)
    assert np.linalg.norm(decoded - cgh.decode_points(a), axis=-1).max() <= 2e-4 * report.bbox_diagonal


def test_an_mlp_that_could_overflow_float32_is_refused():
    """Finite but enormous weights (a crafted file) would overflow when decoding to Gaussians; the
    asset's own bound on the MLP's outputs refuses them first, with a message that says why."""
    a = example_asset(5)
    a.appearance.mlp[-1].weight[0, 0] = 1e36
    with pytest.raises(AssetError, match="safe range"):
        a.validate()
    a.appearance.mlp[-1].weight[0, 0] = 1e3  # large, yet nowhere near float32's limit
    a.validate()
    data = cgh.encode(a, "lossless")[0]
    big = cgh.decode(data)
    big.appearance.mlp[-1].weight[:] = 1e36
    with pytest.raises(AssetError, match="safe range"):
        cgh.encode(big, "lossless")


@pytest.mark.parametrize(("missing", "nudged"), [(1, True), (100, False)])
def test_an_isolated_miss_nudges_the_step_and_many_tighten_it(missing, nudged, monkeypatch):
    """A point or two beyond the bound is a matter of where the lattice falls: the writer first tries a
    step 1 % smaller. Many points beyond it mean the step is too coarse: it shrinks with the error."""
    real, steps = writer._quantize_geometry, []

    def first_attempt_misses(asset, prof, step, diag, points, tol, choices, family):
        geometry = real(asset, prof, step, diag, points, tol, choices, family)
        steps.append(step)
        if len(steps) == 1:  # move ``missing`` points 1.2 tolerances off their input
            decoded = geometry.decoded_points.copy()
            decoded.reshape(-1, 3)[:missing] = points.reshape(-1, 3)[:missing] + [1.2 * tol, 0, 0]
            geometry = geometry._replace(decoded_points=decoded)
        return geometry

    monkeypatch.setattr(writer, "_quantize_geometry", first_attempt_misses)
    data, report = cgh.encode(example_asset(0), "compact")
    assert len(steps) == 2 and report.step == steps[1]
    if nudged:
        assert steps[1] == pytest.approx(writer.NUDGE * steps[0])
    else:
        assert steps[1] == pytest.approx(writer.TIGHTEN_TARGET / 1.2 * steps[0])


@pytest.mark.parametrize("recurring", [writer.NUDGES, writer.NUDGES + 1])
def test_a_recurring_isolated_miss_is_nudged_up_to_nudges_times(recurring, monkeypatch):
    """A point far off its card misses wherever the lattice falls badly, at any step: each nudge is a new
    fall of the lattice, and only after NUDGES of them does the step shrink with the error."""
    real, steps = writer._quantize_geometry, []

    def isolated_misses(asset, prof, step, diag, points, tol, choices, family):
        geometry = real(asset, prof, step, diag, points, tol, choices, family)
        steps.append(step)
        if len(steps) <= recurring:
            decoded = geometry.decoded_points.copy()
            decoded.reshape(-1, 3)[0] = points.reshape(-1, 3)[0] + [1.2 * tol, 0, 0]
            geometry = geometry._replace(decoded_points=decoded)
        return geometry

    monkeypatch.setattr(writer, "_quantize_geometry", isolated_misses)
    _, report = cgh.encode(example_asset(0), "compact")
    assert len(steps) == recurring + 1 and report.step == steps[-1]
    nudged = min(recurring, writer.NUDGES)
    assert steps[1:nudged + 1] == pytest.approx([steps[0] * writer.NUDGE ** (i + 1) for i in range(nudged)])
    if recurring > writer.NUDGES:
        assert steps[-1] == pytest.approx(writer.TIGHTEN_TARGET / 1.2 * steps[-2])


@pytest.mark.parametrize("mean, within", [(None, 15), (0.5, 31), (0.1, 127), (0.02, 255)])
def test_low_opacities_take_a_finer_step_the_file_records(mean, within):
    """compact halves its opacity step (within 1/15, 1/31, ... 1/255) until the mean rounding error is at
    most opacity_error of the mean opacity: the coarsest such step, recorded in META, each opacity
    decoding within half of it; high and lossless keep their own. (mean None: uniform opacities.)"""
    a = example_asset(4, strands=60, points=24)
    rng = np.random.default_rng(2)
    drawn = rng.uniform(0, 1, a.opacity.shape) if mean is None else rng.exponential(mean, a.opacity.shape)
    a.opacity = np.clip(drawn, 0, 1).astype(np.float32)
    compact = cgh.PROFILES["compact"]
    data, report = cgh.encode(a, "compact")
    scale = quant_of(data)["opacity_scale"]
    assert 2 * scale == within and cgh.read_info(data)["opacities"]["within"] == 0.5 / scale
    assert np.abs(cgh.decode(data).opacity - report.in_file_order(a).opacity).max() <= 0.5 / scale + 1e-7
    o = a.opacity[a.real_segments()].astype(np.float64)
    error = [np.abs(np.round(o * s) / s - o).mean() for s in (scale, (scale - 0.5) / 2)]
    assert error[0] <= compact.opacity_error * o.mean() or within == 255
    assert within == 15 or error[1] > compact.opacity_error * o.mean()
    for profile in ("high", "lossless"):
        assert cgh.PROFILES[profile].for_opacities(o) is cgh.PROFILES[profile]
