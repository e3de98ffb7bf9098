"""Regenerate the conformance vectors in this folder: ``python spec/vectors/generate.py``.

Valid files come with ``NAME.expected.npz`` (decoded points and Gaussians, float32; a file with PCNT
adds ``point_counts``, its ``points`` keep the placeholders; an animated file each frame's cards and
points: spec 9). Must-reject files are listed in ``reject.json`` with the error class and a fragment of
its message (and ``"animation": true`` where only a reader of the animation refuses it).
``python spec/vectors/generate.py --animation`` writes the animation's vectors alone (spec 4.6).
"""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

import numpy as np
import zstandard

import cghair_format as cgh
from cghair_format import container
from cghair_format.examples import example_animation, example_asset, with_interpolated_strands, with_point_counts
from cghair_format.geometry import strand_points
from cghair_format.streams import StreamWriter

HERE = Path(__file__).resolve().parent


def _expected(name: str, data: bytes) -> None:
    (HERE / f"{name}.cgh").write_bytes(data)
    asset = cgh.decode(data)
    g = cgh.decode_gaussians(asset)
    counts = {"point_counts": asset.point_counts} if asset.variable else {}
    clip = cgh.read_animation(data)
    frames = {} if clip is None else {
        "frame_spine": clip.spine, "frame_normal": clip.normal,
        "frame_points": np.stack([strand_points(clip.cards(asset.cards, f), asset.strand_card, asset.uvd)
                                  for f in range(clip.frames)])}
    np.savez_compressed(HERE / f"{name}.expected.npz", points=strand_points(asset.cards, asset.strand_card, asset.uvd),
                        means=g.means, rotations=g.rotations, scales=g.scales, opacities=g.opacities, sh=g.sh, **counts,
                        **frames)


def _rechunk(data: bytes, edit) -> bytes:
    """Unpack, let ``edit`` change the chunk list, pack again with valid checksums."""
    _, infos, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    chunks = [container.Chunk(i.type, payloads[i.type], i.required) for i in infos]
    return container.pack(edit(chunks))


def _meta_edit(chunks, change):
    meta = json.loads(chunks[0].payload)
    change(meta)
    chunks[0] = container.Chunk("META", json.dumps(meta).encode())
    return chunks


def _quant(data: bytes) -> dict:
    payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))[2]
    return json.loads(payloads["META"])["quant"]


def _encode(asset, profile: str, guide: int, classes: int | None = None, level_guide: bool = False) -> bytes:
    """``cgh.encode`` with the writer's choices of ``base_guide`` and ``level_guide`` (spec 4.3) and, if
    given, of ``neighbour_classes`` (4.3.2) forced: the small vectors then cover each way a decoder must
    go, whichever the writer would pick for them."""
    from cghair_format.codec import choices, chunks

    choose, write, levels = choices.choose_base_samples, chunks.write_residuals, choices.choose_level_guide
    choices.choose_base_samples = lambda *args: (choose(*args)[0], guide)
    choices.choose_level_guide = lambda *args: level_guide
    if classes is not None:  # the file's STRD only (the chunk writer's), not the writer's trial codings
        chunks.write_residuals = lambda w, arrays, card=None, tried=(1,): write(w, arrays, card, (classes,))
    try:
        data = cgh.encode(asset, profile)[0]
    finally:
        choices.choose_base_samples, chunks.write_residuals, choices.choose_level_guide = choose, write, levels
    assert _quant(data)["base_guide"] == guide and _quant(data)["level_guide"] == level_guide
    assert classes is None or _quant(data)["neighbour_classes"] == classes
    return data


def _differs(data: bytes, change: dict) -> None:
    """Assert that ``data`` with its META quant changed so is refused or decodes to points more than
    1e-3 away: a decoder that ignores the field fails the vector."""
    other = _rechunk(data, lambda c: _meta_edit(c, lambda m: m["quant"].update(change)))
    try:
        points = cgh.decode_points(cgh.decode(other))
    except cgh.CghFormatError:
        return
    assert not np.allclose(points, cgh.decode_points(cgh.decode(data)), rtol=0, atol=1e-3), change


def main() -> None:
    minimal = example_asset(1, strands=3, points=2, cards=1, segments=1, groups=1, k=1, latent_dim=1, hidden=1,
                            sh_degree=0, weight_mode="hard")
    compact = _small_vectors(minimal)
    built = _synth_vectors()
    children, family = _children_vector(built)
    counts_file = _variable_counts_vector(built)
    _reject_vectors(minimal, compact, children, family, counts_file)
    _lowered_vectors()
    _tolerance_vectors()
    _animation_vectors()


def _animation_vectors() -> None:
    """Animated files (spec 4.6): 40 frames in two blocks, compact and lossless, and the must-reject ones,
    added to reject.json."""
    asset = example_asset(5, strands=12, points=6, cards=3, segments=4)
    clip = example_animation(asset.cards, 40)
    compact = cgh.encode(asset, "compact", animation=clip)[0]
    lossless = cgh.encode(asset, "lossless", animation=clip)[0]
    _expected("animated_compact", compact)
    _expected("animated_lossless", lossless)
    reject = json.loads((HERE / "reject.json").read_text())

    def bad(name: str, data: bytes, error: str, fragment: str) -> None:
        (HERE / f"{name}.cgh").write_bytes(data)
        reject[f"{name}.cgh"] = {"error": error, "message": fragment, "animation": True}

    def with_anim(data: bytes, payload: bytes) -> bytes:
        return _stored_anim(data, payload, container.CODEC_RAW, payload)

    anim = container.unpack(compact, set(cgh.codec.KNOWN_CHUNKS))[2]["ANIM"]
    stored, raw, kind = struct.unpack_from("<IIB", anim, 16)  # block 1's entry
    bad("reject_anim_block_outside", with_anim(compact, anim[:16] + struct.pack("<IIB", stored + 4096, raw, kind)
                                               + anim[25:]), "LimitError", "past the chunk")
    bad("reject_anim_frame_count", _rechunk(compact, lambda c: _meta_edit(c, lambda m: m["animation"].update(
        frames=70))), "InvalidContentError", "block count")
    whole = zstandard.ZstdCompressor(level=19, write_content_size=True).compress(anim)
    bad("reject_anim_compressed", _stored_anim(compact, anim, container.CODEC_ZSTD, whole),
        "InvalidContentError", "stored raw")
    bad("reject_anim_without_meta", _rechunk(compact, lambda c: _meta_edit(c, lambda m: m.pop("animation"))),
        "InvalidContentError", "exactly when")
    bad("reject_anim_nan_frame", with_anim(lossless, _nan_first_block(lossless)), "InvalidContentError", "NaN")
    (HERE / "reject.json").write_text(json.dumps(reject, indent=2) + "\n")


def _lowered_vectors() -> None:
    """A compact file whose writer lowered the opacities marked negligible (spec 4.4, "Lowered opacities"),
    and the must-reject file that says it lowered more opacities than it holds, added to reject.json."""
    asset = example_asset(1, strands=12, points=8, cards=8, segments=6, k=4)
    rng = np.random.default_rng(1)
    asset.opacity = rng.random(asset.opacity.shape).astype(np.float32)  # rough, so the marks pay
    negligible = rng.random(asset.opacity.shape) < 0.5
    data, report = cgh.encode(asset, "compact", negligible=negligible, opacity_budget=0.1)
    assert report.opacity.kept, "the marks must pay for the vector to record lowered opacities"
    _expected("lowered_opacities_compact", data)
    held = asset.opacity.size
    (HERE / "reject_opacity_lowered.cgh").write_bytes(_rechunk(data, lambda c: _meta_edit(
        c, lambda m: m["quant"].update(opacity_lowered=held + 1))))
    reject = json.loads((HERE / "reject.json").read_text())
    reject["reject_opacity_lowered.cgh"] = {"error": "InvalidContentError", "message": "opacity_lowered"}
    (HERE / "reject.json").write_text(json.dumps(reject, indent=2) + "\n")


def _tolerance_vectors() -> None:
    """A compact file whose points were held to a bound of the user's (spec 7, META
    ``quant.position_tolerance``), and the must-reject file whose bound is out of range, added to
    reject.json."""
    asset = example_asset(2, strands=12, points=8, cards=4, segments=6, k=4)
    data = cgh.encode(asset, cgh.PROFILES["compact"].with_position_tolerance(2e-3))[0]
    assert _quant(data)["position_tolerance"] == 2e-3
    _expected("loose_points_compact", data)
    (HERE / "reject_position_tolerance.cgh").write_bytes(_rechunk(data, lambda c: _meta_edit(
        c, lambda m: m["quant"].update(position_tolerance=0))))
    reject = json.loads((HERE / "reject.json").read_text())
    reject["reject_position_tolerance.cgh"] = {"error": "InvalidContentError", "message": "position_tolerance"}
    (HERE / "reject.json").write_text(json.dumps(reject, indent=2) + "\n")


def _stored_anim(data: bytes, payload: bytes, kind: int, body: bytes) -> bytes:
    """``data`` with ANIM's payload ``payload``, stored as ``body`` with codec ``kind``."""
    _, infos, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    stored = [container.Stored(container.Chunk(i.type, payload, False), kind, body) if i.type == "ANIM" else
              container.compress(container.Chunk(i.type, payloads[i.type], i.required)) for i in infos]
    return container.assemble(stored)


def _nan_first_block(lossless: bytes) -> bytes:
    """A lossless file's ANIM whose first frame's first spine coordinate is NaN (its first block stored raw)."""
    reader = cgh.animation_reader(lossless)
    clip = reader.animation()
    g = reader.meta["keyframe_interval"]
    spine = clip.spine[:g].copy()
    spine[0, 0, 0, 0] = np.nan
    w = StreamWriter()
    w.array(spine, shuffle=True)
    w.array(clip.normal[:g], shuffle=True)
    first = w.getvalue()
    anim = container.unpack(lossless, set(cgh.codec.KNOWN_CHUNKS))[2]["ANIM"]
    count = struct.unpack_from("<I", anim)[0]
    start = 4 + 12 * count + struct.unpack_from("<I", anim, 4)[0]  # block 1 onwards, as they are
    return (anim[:4] + struct.pack("<IIB3x", len(first), len(first), 0) + anim[16:4 + 12 * count] + first
            + anim[start:])


def _small_vectors(minimal) -> bytes:
    """The minimal and small example assets' vectors; returns the small compact file."""
    small = example_asset(0)
    _expected("minimal_lossless", cgh.encode(minimal, "lossless")[0])
    _expected("minimal_compact", cgh.encode(minimal, "compact")[0])
    compact = cgh.encode(small, "compact")[0]
    _expected("small_compact", compact)
    # base samples unguided (spec 4.3): decoding the file as guided gives other points
    data = _encode(example_asset(2, sh_degree=3, weight_mode="hard"), "high", guide=0)
    _differs(data, {"base_guide": 1})
    _expected("small_high_hard", data)
    extras = example_asset(3, strands=6, points=4)
    extras.strand_ids = np.arange(6, dtype=np.uint32) * 7
    extras.source_color = np.linspace(0, 1, 6 * 4 * 3, dtype=np.float32).reshape(6, 4, 3)
    extras.metadata = {"note": "optional chunks"}
    _expected("optional_chunks", _rechunk(cgh.encode(extras, "compact")[0],
                                          lambda c: c + [container.Chunk("ZEXT", b"future data", required=False)]))
    _expected("newer_minor", container.rewrite_header(compact, minor=9))
    return compact


def _synth_vectors():
    """Grown hair on built cards, straight and curly; returns the straight asset."""
    # real-looking hair: grown strands on built cards, for which the writer picks the world-guided
    # (Newton) prediction of spec section 4.3 (the assertion below keeps it so), with guided base samples
    from cghair_format.cards import build_cards
    from cghair_format.synth import synthesize

    built = build_cards(synthesize("straight", 48, 24, seed=1), n_cards=6, n_groups=2, segments=8, points=24,
                        seed=0, progress=False, sh_degree=1).asset
    data = _encode(built, "compact", guide=1)
    assert _quant(data)["newton_steps"] > 0
    _differs(data, {"base_guide": 0})
    _differs(data, {"base_guide": 2})
    _expected("synth_cards_compact", data)
    # the same with the card neighbour's tokens as context (spec 4.3.2, neighbour_classes 3) and base
    # samples guided by the neighbour's steps scaled (base_guide 2)
    data = _encode(built, "compact", guide=2, classes=3)
    _differs(data, {"base_guide": 1})
    _differs(data, {"neighbour_classes": 1})
    _expected("synth_cards_neighbour_classes", data)
    # curly hair on the same few cards, where the decoder halves some Newton steps and stretches residual
    # steps (spec 4.3), and base samples and level residuals follow the most alike earlier strand
    # (base_guide 3, level_guide 1): decoding it with fewer halvings, unstretched, guided by the card
    # neighbour alone or without level references gives other points (the assertion below keeps it so)
    curly = build_cards(synthesize("curly", 48, 24, seed=2), n_cards=6, n_groups=2, segments=8, points=24,
                        seed=0, progress=False, sh_degree=1).asset
    data = _encode(curly, "compact", guide=3, level_guide=True)
    for change in ({"newton_halvings": 0}, {"newton_halvings": 3}, {"stretch_max": 1}, {"base_guide": 1},
                   {"level_guide": 0}):
        _differs(data, change)
    _expected("synth_curly_compact", data)
    return built


def _children_vector(built):
    """Interpolated strands (spec 4.5): half the strands are blends of others, plain and resampled; a
    decoder that takes none, or resamples none, gets other points. Returns the file and its family."""
    data = cgh.encode(with_interpolated_strands(built, seed=4), "compact")[0]
    assert _quant(data)["children"] > 0
    family = cgh.codec.reader.read_family(container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))[2]["CHLD"],
                                          96 - _quant(data)["children"], _quant(data)["children"])
    assert family.respaced.any() and not family.respaced.all()
    _differs(data, {"children": 0})
    _expected("synth_children_compact", data)
    return data, family


def _variable_counts_vector(built) -> bytes:
    """Strands of their own point counts (spec 3, PCNT), with source colours: placeholders decode as any
    point (section 4) and are then dropped with their Gaussians, SH sets and colours."""
    varied = with_point_counts(built, seed=5)
    varied.source_color = np.linspace(0, 1, varied.uvd.size, dtype=np.float32).reshape(varied.uvd.shape)
    data = cgh.encode(varied, "compact")[0]
    assert cgh.read_info(data)["version"] == "2.1" and cgh.decode(data).variable
    _expected("variable_counts_compact", data)
    return data


def _reject_vectors(minimal, compact: bytes, children: bytes, family, counts_file: bytes) -> None:
    """The must-reject files and reject.json."""
    reject = {}

    def bad(name: str, data: bytes, error: str, fragment: str) -> None:
        (HERE / f"{name}.cgh").write_bytes(data)
        reject[f"{name}.cgh"] = {"error": error, "message": fragment}

    bad("reject_not_cgh", b"ply\nformat binary_little_endian 1.0\n" + compact[40:], "BadMagicError", "not a .cgh")
    bad("reject_truncated", compact[:-100], "TruncatedError", "declares")
    flipped = bytearray(compact)
    flipped[len(compact) // 2] ^= 0x01
    bad("reject_flipped_byte", bytes(flipped), "ChecksumError", "checksum")
    bad("reject_major_3", container.rewrite_header(compact, major=3, minor=0), "UnsupportedVersionError", "version 3.0")
    # a quantized file as format 1.0 wrote it (its bytes aside: 1.0 decoded them with other arithmetic)
    bad("reject_quantized_1_0", container.rewrite_header(compact, major=1, minor=0), "UnsupportedVersionError",
        "rewrite it")
    bad("reject_unknown_required", _rechunk(compact, lambda c: c + [container.Chunk("ZREQ", b"x")]),
        "UnknownRequiredChunkError", "ZREQ")
    bad("reject_missing_chunk", _rechunk(compact, lambda c: [x for x in c if x.type != "OPAC"]),
        "InvalidContentError", "OPAC")
    bad("reject_bad_meta", _rechunk(compact, lambda c: _meta_edit(c, lambda m: m.update(points=1))),
        "InvalidContentError", "points")
    bad("reject_shape_mismatch", _rechunk(compact, lambda c: _meta_edit(c, lambda m: m.update(strands=65))),
        "InvalidContentError", "shape")
    padded = bytearray(cgh.encode(minimal, "lossless")[0])
    padded[-1] = 0xAA
    bad("reject_nonzero_padding", bytes(padded), "CghFormatError", "padding")
    bad("reject_children_without_chld", _rechunk(children, lambda c: [x for x in c if x.type != "CHLD"]),
        "InvalidContentError", "CHLD")
    past = container.Chunk("CHLD", cgh.codec.chunks.family_payload(family._replace(parents=family.parents + (1 << 20))))
    bad("reject_child_parent", _rechunk(children, lambda c: [past if x.type == "CHLD" else x for x in c]),
        "InvalidContentError", "parent")
    long = StreamWriter()
    long.ints(np.full(96, 25))  # one point more than META points
    bad("reject_point_count", _rechunk(counts_file, lambda c: [container.Chunk("PCNT", long.getvalue())
                                                                 if x.type == "PCNT" else x for x in c]),
        "InvalidContentError", "point count")
    (HERE / "reject.json").write_text(json.dumps(reject, indent=2) + "\n")


if __name__ == "__main__":
    _animation_vectors() if sys.argv[1:] == ["--animation"] else main()
