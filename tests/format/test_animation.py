"""The animation part of the format (spec 4.6, chunk ANIM): the stated bound per profile, one frame from its
block alone, the rest pose unchanged, the command line, and hostile ANIM chunks refused where they are wrong."""

import json
import time
from pathlib import Path

import numpy as np
import pytest
import zstandard

import cghair_format as cgh
from cghair_format import container
from cghair_format.animation import Animation
from cghair_format.cli import main as cli_main
from cghair_format.codec.animation import BLOCK_ENTRY, COUNT, AnimationReader
from cghair_format.examples import example_animation, example_asset
from cghair_format.geometry import spine_frames
from cghair_format.limits import ReadLimits
from cghair_format.streams import StreamWriter

pytestmark = pytest.mark.filterwarnings("error")  # refusing bad input must not warn


@pytest.fixture(scope="module")
def asset():
    return example_asset(3, strands=48, points=12, cards=6, segments=5)


@pytest.fixture(scope="module")
def clip(asset):
    return example_animation(asset.cards, 70)


@pytest.fixture(scope="module")
def files(asset, clip):
    return {p: cgh.encode(asset, p, animation=clip) for p in ("compact", "high", "lossless")}


def test_an_animated_file_says_2_1_in_its_header(asset, files):
    """2.1 is the first version that describes ANIM (spec 1.1): a file that moves says so in its header, a
    still one without PCNT stays byte for byte what 2.0 wrote."""
    for data, _ in files.values():
        assert container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))[0] == (2, 1)
    assert container.unpack(cgh.encode(asset, "compact")[0], set(cgh.codec.KNOWN_CHUNKS))[0] == (2, 0)


@pytest.mark.parametrize("profile", ["compact", "high"])
def test_quantized_frames_meet_the_stated_bound(files, clip, profile):
    data, report = files[profile]
    info = cgh.read_info(data)["animation"]
    back = cgh.read_animation(data)
    assert back.frames == clip.frames and back.fps == clip.fps and back.start == clip.start and back.source == "swing"
    qa, bits = info["step"], info["normal_bits"]
    assert np.abs(back.spine.astype(np.float64) - clip.spine).max() <= qa / 2 * (1 + 1e-6) + 1e-7
    # the normal's angle about the decoded spine: from the input normal's part across it (spec 4.6)
    t, _ = spine_frames(back.spine.reshape(-1, clip.spine.shape[2], 3).astype(np.float64))
    n = clip.normal.reshape(t.shape).astype(np.float64)
    across = n - (n * t).sum(-1, keepdims=True) * t
    across /= np.linalg.norm(across, axis=-1, keepdims=True)
    got = back.normal.reshape(t.shape).astype(np.float64)
    angle = np.arctan2(np.linalg.norm(np.cross(across, got), axis=-1), (across * got).sum(-1))
    assert angle.max() <= np.pi / 2**bits + 1e-6  # (float32 normals and spines: within 1e-6)
    assert report.animation.step == qa and report.animation.stored_bytes == info["stored_bytes"]
    assert 0 < report.animation.max_point_error <= 1.5 * {"compact": 2e-4, "high": 2e-5}[profile] * report.bbox_diagonal


def test_lossless_frames_are_exact(files, clip):
    back = cgh.read_animation(files["lossless"][0])
    assert np.array_equal(back.spine, clip.spine) and np.array_equal(back.normal, clip.normal)
    assert files["lossless"][1].animation.max_point_error == 0


@pytest.mark.parametrize("profile", ["compact", "lossless"])
def test_one_frame_decodes_from_its_block_alone(files, profile):
    data = files[profile][0]
    every = cgh.read_animation(data)
    reader = cgh.animation_reader(data)
    g = reader.meta["keyframe_interval"]
    for t in (0, g - 1, g, 2 * g + 3, every.frames - 1):
        cards = reader.frame(t)
        assert np.array_equal(cards.spine, every.spine[t]) and np.array_equal(cards.normal, every.normal[t])
    # frame t needs no byte of another block: spoil every other block's body and t still decodes alike
    t = 2 * g + 3
    meta = {"animation": reader.meta, "quant": {"lossless": reader.lossless}}
    spoilt = AnimationReader(meta, _spoil_others(reader, t // g), reader._offset, reader.rest, ReadLimits())
    assert np.array_equal(spoilt.frame(t).spine, every.spine[t])
    with pytest.raises(cgh.CghFormatError):
        spoilt.frame(0)


def _spoil_others(reader, keep: int) -> bytes:
    payload = bytearray(reader._payload)
    for b, (start, stored, _, _) in enumerate(reader._blocks):
        if b != keep:
            payload[start:start + stored] = b"\xff" * stored
    return bytes(payload)


@pytest.mark.parametrize("profile", ["compact", "lossless"])
def test_the_rest_pose_reads_as_without_the_animation(asset, files, profile):
    data = files[profile][0]
    plain = cgh.encode(asset, profile)[0]
    _, with_anim, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    _, without, plain_payloads = container.unpack(plain, set(cgh.codec.KNOWN_CHUNKS))
    assert [i.type for i in with_anim] == [i.type for i in without] + ["ANIM"]
    assert not next(i for i in with_anim if i.type == "ANIM").required  # a reader that does not know it skips it
    assert all(payloads[k] == plain_payloads[k] for k in plain_payloads if k != "META")
    a, b = cgh.read(data), cgh.read(plain)
    assert np.array_equal(a.uvd, b.uvd) and np.array_equal(a.cards.spine, b.cards.spine)
    assert cgh.read_animation(plain) is None and cgh.read_info(plain)["animation"] is None


def test_cli_shows_validates_and_keeps_the_animation(tmp_path, files, capsys):
    src = tmp_path / "anim.cgh"
    src.write_bytes(files["high"][0])
    assert cli_main(["info", str(src)]) == 0
    out = capsys.readouterr().out
    assert "animation   70 frames at 30 fps from 0.5 s (2.3 s), a keyframe every 32" in out and "from swing" in out
    assert cli_main(["validate", str(src), "--reference"]) == 0
    out = capsys.readouterr().out
    assert "animation: 70 frames" in out and "the same cards on all 70 animation frames, bit for bit" in out
    assert cli_main(["validate", str(NAN_VECTOR)]) == 1  # refused, and not called valid first
    captured = capsys.readouterr()
    assert "valid" not in captured.out and "holds NaN" in captured.err
    out_file = tmp_path / "compact.cgh"
    assert cli_main(["encode", str(src), "-o", str(out_file), "--profile", "compact"]) == 0
    assert "animation: 70 frames at 30 fps" in capsys.readouterr().out
    high, compact = cgh.read_animation(src), cgh.read_animation(out_file)
    qa = cgh.read_info(out_file)["animation"]["step"]
    assert np.abs(compact.spine - high.spine).max() <= qa / 2 * (1 + 1e-6) + 1e-7


def test_the_writer_refuses_frames_that_do_not_fit(asset, clip):
    with pytest.raises(cgh.AssetError, match="frames must be"):
        cgh.encode(asset, animation=Animation(clip.spine[:, :2], clip.normal[:, :2], 30.0))
    bad = Animation(clip.spine.copy(), clip.normal, 30.0)
    bad.spine[3, 0, 0, 0] = np.nan
    with pytest.raises(cgh.AssetError, match="frame 3"):
        cgh.encode(asset, animation=bad)


# --- hostile ANIM chunks: refused naming ANIM (or META) and a byte offset, at once --------------------------

def _anim(data: bytes) -> tuple[container.ChunkInfo, bytes]:
    _, infos, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    return next(i for i in infos if i.type == "ANIM"), payloads["ANIM"]


def _with_anim(data: bytes, payload: bytes, codec: int = container.CODEC_RAW) -> bytes:
    _, infos, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    stored = []
    for i in infos:
        chunk = container.Chunk(i.type, payloads[i.type], i.required)
        if i.type == "ANIM":
            body = payload if codec == container.CODEC_RAW else zstandard.ZstdCompressor(
                write_content_size=True).compress(payload)
            stored.append(container.Stored(container.Chunk("ANIM", payload, False), codec, body))
        else:
            stored.append(container.compress(chunk, 3))
    return container.assemble(stored)


def _entry(payload: bytes, b: int, stored: int | None = None, raw: int | None = None) -> bytes:
    at = COUNT.size + BLOCK_ENTRY.size * b
    s, r, codec = BLOCK_ENTRY.unpack_from(payload, at)
    return payload[:at] + BLOCK_ENTRY.pack(s if stored is None else stored, r if raw is None else raw, codec) + \
        payload[at + BLOCK_ENTRY.size:]


def _meta_frames(data: bytes, frames: int) -> bytes:
    _, infos, payloads = container.unpack(data, set(cgh.codec.KNOWN_CHUNKS))
    meta = json.loads(payloads["META"])
    meta["animation"]["frames"] = frames
    payloads["META"] = json.dumps(meta).encode()
    return container.assemble([container.compress(container.Chunk(i.type, payloads[i.type], i.required), 3)
                               for i in infos])


# spec/vectors/generate.py's lossless file with the first frame's first spine value NaN (two blocks)
NAN_VECTOR = Path(__file__).resolve().parents[2] / "spec" / "vectors" / "reject_anim_nan_frame.cgh"

HOSTILE = {
    "block count that lies": (lambda d, p: _with_anim(d, COUNT.pack(7) + p[4:]), "ANIM", None),
    "block table past the chunk": (lambda d, p: _with_anim(d, p[:COUNT.size + 5]), "ANIM", None),
    "block pointing outside": (lambda d, p: _with_anim(d, _entry(p, 1, stored=1 << 30)), "ANIM", None),
    "raw size that lies": (lambda d, p: _with_anim(d, _entry(p, 0, raw=1 << 31)), "ANIM", None),
    "raw size a byte short": (lambda d, p: _with_anim(d, _entry(p, 0, raw=BLOCK_ENTRY.unpack_from(p, 4)[1] - 1)),
                              "ANIM", None),
    "bytes after the last block": (lambda d, p: _with_anim(d, p + b"\0"), "ANIM", None),
    "ANIM compressed as a whole": (lambda d, p: _with_anim(d, p, container.CODEC_ZSTD), "ANIM", None),
    "frames over the limit": (lambda d, p: d, "META", ReadLimits(max_frames=10)),
    "decoded bytes over the limit": (lambda d, p: d, "ANIM", ReadLimits(max_decoded_bytes=40_000)),
    "frame count that lies": (lambda d, p: _meta_frames(d, 200), "ANIM", None),
    "META frames 2^21": (lambda d, p: _meta_frames(d, 1 << 21), "META", None),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_anim_is_refused_where_it_is_wrong(files, case):
    build, chunk, limits = HOSTILE[case]
    data = files["compact"][0]
    bad = build(data, _anim(data)[1])
    start = time.perf_counter()
    with pytest.raises(cgh.CghFormatError) as exc:
        cgh.read_animation(bad, limits)
    assert time.perf_counter() - start < 1.0
    assert exc.value.chunk == chunk and exc.value.offset is not None, exc.value
    if chunk == "ANIM":
        info, _ = _anim(bad)
        assert info.offset <= exc.value.offset <= info.offset + info.stored, exc.value
    if chunk == "ANIM":  # the rest pose reads on (META is checked by every reader that knows its fields)
        assert cgh.read(bad).n_strands == 48


def test_nan_in_a_lossless_frame_is_refused():
    reader = cgh.animation_reader(NAN_VECTOR)
    with pytest.raises(cgh.CghFormatError, match="frame 0 holds NaN") as exc:
        reader.frame(1)
    assert exc.value.chunk == "ANIM" and exc.value.offset is not None
    assert np.isfinite(reader.frame(39).spine).all()  # its other block decodes


def test_a_spine_beyond_the_format_s_lengths_is_refused_with_its_frame(asset):
    """A keyframe residual that puts a spine at 2^60 steps decodes, in int64, beyond 10^12 units."""
    data = cgh.encode(asset, "compact", animation=example_animation(asset.cards, 40))[0]
    reader = cgh.animation_reader(data)
    start, stored, raw, _ = reader._blocks[1]
    w = StreamWriter()
    shape = (8, *asset.cards.spine.shape)
    spine = np.zeros(shape, np.int64)
    spine[0, 0, 0, 0] = 1 << 60
    w.ints(spine)
    w.ints(np.zeros(shape[:-1], np.int64))
    body = w.getvalue()
    payload = bytes(reader._payload)
    first = reader._blocks[0]
    table = COUNT.pack(2) + BLOCK_ENTRY.pack(first[1], first[2], first[3]) + BLOCK_ENTRY.pack(len(body), len(body), 0)
    bad = _with_anim(data, table + payload[first[0]:first[0] + first[1]] + body)
    reader = cgh.animation_reader(bad)
    assert np.isfinite(reader.frame(31).spine).all()
    with pytest.raises(cgh.CghFormatError, match="block 1: an animation frame's spine lies beyond") as exc:
        reader.frame(35)
    assert exc.value.chunk == "ANIM" and exc.value.offset is not None
