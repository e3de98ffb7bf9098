"""The animation part (spec 4.6): an :class:`~..animation.Animation`'s card strips <-> the ANIM chunk.

Frames come in blocks of ``keyframe_interval`` (``G``) frames, each compressed on its own behind a small
table of block sizes, so frame ``t`` decodes from its block alone. Quantized, a frame's spine is stored as
integers ``round(spine / qa)`` and its normals as angles about its own spine in ``2^normal_bits`` steps a
turn, exactly as CARD codes the rest cards (spec 4.2). A block's first frame (the keyframe) is predicted
from the rest cards' integers (its angles from none), every later frame from the frames before it in the
block, and the residuals are differenced along each card. Lossless: the float32 arrays as they are. The
writer's step search (:func:`encode_within`) and the reader (:class:`AnimationReader`) are here too.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
import zstandard

from .. import container
from ..animation.clip import Animation
from ..asset import MAX_LENGTH, Cards
from ..errors import AssetError, InvalidContentError, LimitError
from ..geometry import angle_normals, normal_angles, spine_frames
from ..limits import FLOAT, ReadLimits, animation_bytes
from ..profiles import Profile
from ..streams import StreamReader, StreamWriter
from .animation_error import PointBoxes, animation_point_error
from .layout import ANIM_CHUNK

BLOCK_ENTRY = struct.Struct("<IIB3x")  # stored size, raw size, codec (0 raw, 1 zstd), 3 zero bytes
COUNT = struct.Struct("<I")
SPINE_HEADER, ANGLE_HEADER = 4 + 4 * 4, 4 + 3 * 4  # the array records' headers (4 and 3 dims, spec 2)
MAX_INT_BYTES = 8  # the widest integer an ``ints`` record may hold
DEFAULT_KEYFRAME_INTERVAL = 32  # a second at 30 fps: docs/format.md, "Animation"
STEP_FRACTION = 0.5  # the spine step qa, as a fraction of the profile's point tolerance (docs/format.md, "Animation")
MAX_TIGHTENINGS, TIGHTEN_TARGET = 6, 0.97  # the step search (:func:`encode_within`), as the strands' writer's
SAFE_INTEGER = 2.0**53  # spine integers beyond this lose exactness in float64


@dataclass(frozen=True)
class AnimationReport:
    """What the writer measured of the animation it stored (``EncodeReport.animation``)."""

    frames: int
    fps: float
    stored_bytes: int  # the ANIM chunk
    step: float | None  # qa, scene units (None: lossless)
    normal_bits: int | None
    max_point_error: float  # the largest distance of a strand point on a decoded frame from it on the input frame

    @property
    def bytes_per_frame(self) -> float:
        return self.stored_bytes / self.frames

    def summary(self, diagonal: float) -> str:
        """The figures in a line, as ``cgh encode`` prints them."""
        precision = "float32 (lossless)" if self.step is None else (
            f"spine step {self.step:.3g}, normals in 2^{self.normal_bits} steps a turn")
        return (f"animation: {self.frames:,} frames at {self.fps:g} fps, {self.stored_bytes:,} bytes "
                f"({self.bytes_per_frame:,.0f} a frame), {precision}; points within {self.max_point_error:.3g} "
                f"({self.max_point_error / max(diagonal, 1e-30):.2e} of the bbox diagonal) of the input frames'")


def animation_meta(animation: Animation, rest: Cards, prof: Profile, diag: float, step: float | None = None,
                   keyframe_interval: int = DEFAULT_KEYFRAME_INTERVAL) -> dict:
    """META's ``animation`` object (spec 2.1) for ``animation`` of ``rest`` at the profile ``prof``:
    quantized, the spine step ``step`` (default: :data:`STEP_FRACTION` of the profile's point tolerance;
    spine coordinates within ``step / 2``), and the fewest normal bits that keep a rail within
    ``step / 2`` of its place as the normal turns by its bound (``reach``: the widest half-width)."""
    meta = {"frames": animation.frames, "fps": float(animation.fps), "start": float(animation.start),
            "keyframe_interval": int(min(keyframe_interval, animation.frames)), "source": animation.source}
    if prof.lossless:
        return meta
    qa = STEP_FRACTION * prof.position_tolerance * max(diag, 1e-12) if step is None else step
    reach = float(np.max(rest.half_width, initial=0.0)) + qa
    bits = int(np.clip(np.ceil(np.log2(2 * np.pi * reach / qa)), 8, 24))
    return meta | {"step": qa, "normal_bits": bits}


def encode_within(animation: Animation, rest: Cards, prof: Profile, diag: float, uvd: np.ndarray,
                  strand_card: np.ndarray) -> tuple[dict, bytes, AnimationReport]:
    """META's ``animation``, ANIM's payload and the report, at the largest step the search finds (from
    :func:`animation_meta`'s, smaller while some strand point, ``uvd`` on ``strand_card``, lies farther than
    the profile's tolerance from its place on the input frames): a spine's error turns its tangent, and
    so the card's rails, by more where a segment is short against the card's width. Each step tried is
    measured exactly (:func:`.animation_error.animation_point_error`); only the one kept is compressed."""
    tol = prof.position_tolerance * max(diag, 1e-12)
    meta = animation_meta(animation, rest, prof, diag)
    boxes = PointBoxes.of(uvd, strand_card, rest.count, rest.segments)
    for _ in range(MAX_TIGHTENINGS):
        blocks, decoded = encode_blocks(animation, rest, meta)
        error = animation_point_error(boxes, animation, decoded, rest, uvd)
        if prof.lossless or error <= tol:
            break
        meta = animation_meta(animation, rest, prof, diag, meta["step"] * TIGHTEN_TARGET * tol / error)
    payload = _pack_blocks(blocks, prof.zstd_level)
    report = AnimationReport(animation.frames, animation.fps, len(payload), meta.get("step"), meta.get("normal_bits"),
                             error)
    return meta, payload, report


def encode_animation(animation: Animation, rest: Cards, meta: dict, level: int) -> tuple[bytes, Animation]:
    """ANIM's payload for ``animation`` of the decoded ``rest`` cards as META's ``animation`` object
    (``meta``) says, and the frames a decoder will get from it."""
    blocks, decoded = encode_blocks(animation, rest, meta)
    return _pack_blocks(blocks, level), decoded


def encode_blocks(animation: Animation, rest: Cards, meta: dict) -> tuple[list[bytes], Animation]:
    """:func:`encode_animation`'s blocks before compression, and the frames a decoder will get."""
    g = meta["keyframe_interval"]
    if "step" in meta:
        spine_q, angles, frames = quantize_frames(animation, meta["step"], meta["normal_bits"])
        decoded = decode_quantized(spine_q, angles, meta["step"], meta["normal_bits"], frames)
        base = rest_integers(rest.spine, meta["step"])
        blocks = [_quantized_block(spine_q[f:f + g], angles[f:f + g], base, meta["normal_bits"])
                  for f in range(0, animation.frames, g)]
    else:
        decoded = (animation.spine.astype(np.float32), animation.normal.astype(np.float32))
        blocks = []
        for f in range(0, animation.frames, g):
            w = StreamWriter()
            w.array(decoded[0][f:f + g], shuffle=True)
            w.array(decoded[1][f:f + g], shuffle=True)
            blocks.append(w.getvalue())
    return blocks, Animation(decoded[0], decoded[1], animation.fps, animation.start, animation.source)


def quantize_frames(animation: Animation, qa: float, bits: int) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Each frame's spine integers ``[F, C, M+1, 3]`` and normal angles ``[F, C, M+1]`` in ``0 .. 2^bits-1``,
    the angles about the spine as a decoder will have it; and that spine's frames (:func:`spine_frames`
    of every frame's cards, as one list of cards), which :func:`decode_quantized` takes again."""
    spine_q = np.rint(animation.spine.astype(np.float64) / qa).astype(np.int64)
    turn = 1 << bits
    m1 = spine_q.shape[2]  # (the cards of every frame, as one list of cards)
    spine = (spine_q * qa).reshape(-1, m1, 3)
    frames = spine_frames(spine)
    angles = normal_angles(animation.normal.reshape(-1, m1, 3), spine, bits, frames)
    return spine_q, np.rint(angles).astype(np.int64).reshape(spine_q.shape[:-1]) % turn, frames


def decode_quantized(spine_q: np.ndarray, angles: np.ndarray, qa: float, bits: int, frames: tuple | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Spine and normals (float32) of frames given as integers (spec 4.6's last step); ``frames``: the
    spine's frames where the caller has them (:func:`quantize_frames`)."""
    spine = spine_q.astype(np.float64) * qa
    with np.errstate(over="ignore", invalid="ignore"):
        spine32 = spine.astype(np.float32)
    if not (np.isfinite(spine32).all() and (np.abs(spine) <= MAX_LENGTH).all()):
        raise InvalidContentError(f"an animation frame's spine lies beyond {MAX_LENGTH:g} scene units (a corrupt "
                                  "step or residuals)", chunk=ANIM_CHUNK)
    m1 = spine.shape[2]
    normal = angle_normals(angles.reshape(-1, m1), spine.reshape(-1, m1, 3), bits, frames).reshape(spine.shape)
    return spine32, normal.astype(np.float32)


def rest_integers(rest_spine: np.ndarray, qa: float) -> np.ndarray:
    """``round(rest spine / qa)``: what a keyframe's spine residuals are taken from (spec 4.6)."""
    x = np.rint(rest_spine.astype(np.float64) / qa)
    if not (np.abs(x) < SAFE_INTEGER).all():
        raise InvalidContentError("META animation.step is too small for the rest cards: their spine in steps "
                                  "exceeds 2^53", chunk="META")
    return x.astype(np.int64)


def _wrap(x: np.ndarray, bits: int) -> np.ndarray:
    """``x`` mod ``2^bits``, in ``-2^(bits-1) .. 2^(bits-1)-1``."""
    half = 1 << (bits - 1)
    return (x + half) % (1 << bits) - half


def _quantized_block(spine_q: np.ndarray, angles: np.ndarray, base: np.ndarray, bits: int) -> bytes:
    """One block's records (spec 4.6): the spine residuals ``ints[n, C, M+1, 3]``, then the angles'
    ``ints[n, C, M+1]``, each the difference of a frame's integers from their prediction (the rest
    cards', or the frames before), differenced again along the card."""
    spine_e = np.empty_like(spine_q)
    spine_e[0] = spine_q[0] - base
    spine_e[1:2] = spine_q[1:2] - spine_q[0:1]
    spine_e[2:] = spine_q[2:] - (2 * spine_q[1:-1] - spine_q[:-2])
    angle_e = angles.copy()
    angle_e[1:] = angles[1:] - angles[:-1]
    w = StreamWriter()
    w.ints(np.diff(spine_e, axis=2, prepend=0))
    w.ints(_wrap(np.diff(angle_e, axis=2, prepend=0), bits))
    return w.getvalue()


def _pack_blocks(blocks: list[bytes], level: int) -> bytes:
    """The block count, the table of block sizes, then the blocks, each zstd where that is smaller."""
    compressor = zstandard.ZstdCompressor(level=level, write_content_size=True)
    table, bodies = [COUNT.pack(len(blocks))], []
    for raw in blocks:
        z = compressor.compress(raw)
        codec, body = (1, z) if len(z) < len(raw) else (0, raw)
        table.append(BLOCK_ENTRY.pack(len(body), len(raw), codec))
        bodies.append(body)
    return b"".join(table + bodies)


def block_bounds(c: int, m1: int, lossless: bool, frames: int) -> tuple[int, int]:
    """The fewest and most raw bytes a block of ``frames`` frames may hold: its two records' headers, and
    lossless 4 bytes a float, quantized 1 to 8 bytes an integer (spec 1.4)."""
    if lossless:
        size = 2 * SPINE_HEADER + FLOAT * frames * c * m1 * 6
        return size, size
    values = frames * c * m1 * 4
    return SPINE_HEADER + ANGLE_HEADER + values, SPINE_HEADER + ANGLE_HEADER + MAX_INT_BYTES * values


class AnimationReader:
    """Frames of a file's ANIM chunk, one block at a time: ``frame(t)`` decodes frame ``t``'s block (at
    most ``keyframe_interval`` frames) and nothing else. ``payload`` is ANIM's (stored raw, spec 4.6),
    ``offset`` where it starts in the file (for refusals), ``rest`` the file's decoded rest cards."""

    def __init__(self, meta: dict, payload: bytes, offset: int, rest: Cards, limits: ReadLimits) -> None:
        self.meta, self.rest, self._payload, self._offset = meta["animation"], rest, memoryview(payload), offset
        self.lossless = meta["quant"]["lossless"]
        if self.lossless != ("step" not in self.meta):
            raise InvalidContentError("META animation must have step and normal_bits exactly when quant is not "
                                      "lossless", chunk="META")
        self.frames, self.fps, self.start = self.meta["frames"], float(self.meta["fps"]), float(self.meta["start"])
        if self.frames > limits.max_frames:
            raise LimitError(f"the animation has {self.frames:,} frames, more than this reader's limit of "
                             f"{limits.max_frames:,} (read_animation(..., limits=ReadLimits(max_frames=N)))",
                             chunk="META")
        self._limits = limits
        self._check_bytes(min(self.meta["keyframe_interval"], self.frames), len(payload), "a block of")
        self._blocks = self._read_table()
        self._base = None if self.lossless else rest_integers(rest.spine, self.meta["step"])
        self._cache: tuple[int, tuple[np.ndarray, np.ndarray]] | None = None

    def _check_bytes(self, frames: int, raw: int, what: str) -> None:
        """Refuse to decode ``frames`` frames from ``raw`` bytes beyond the reader's decoded-bytes limit."""
        c, m1 = self.rest.half_width.shape
        need = animation_bytes(frames, c, m1 - 1) + raw
        if need > self._limits.max_decoded_bytes:
            raise LimitError(f"decoding {what} {frames:,} animation frames takes {need:,} bytes, more than this "
                             f"reader's limit of {self._limits.max_decoded_bytes:,} (raise it with cgh "
                             "--max-decoded-mb M, or ReadLimits(max_decoded_bytes=N))", chunk=ANIM_CHUNK,
                             offset=self._offset)

    def _fail(self, message: str, at: int, kind=InvalidContentError):
        raise kind(message, chunk=ANIM_CHUNK, offset=self._offset + at)

    def _read_table(self) -> list[tuple[int, int, int, int]]:
        """Each block's (start in the payload, stored, raw, codec), checked against the payload and META."""
        g = self.meta["keyframe_interval"]
        want = -(-self.frames // g)
        data = self._payload
        if len(data) < COUNT.size or COUNT.unpack_from(data)[0] != want:
            self._fail(f"the block count must be {want} ({self.frames} frames, a keyframe every {g})", 0)
        if len(data) < COUNT.size + BLOCK_ENTRY.size * want:
            self._fail(f"the table of {want} blocks runs past the chunk's {len(data)} bytes", 0, LimitError)
        c, m1 = self.rest.half_width.shape
        blocks, start = [], COUNT.size + BLOCK_ENTRY.size * want
        for b in range(want):
            at = COUNT.size + BLOCK_ENTRY.size * b
            stored, raw, codec = BLOCK_ENTRY.unpack_from(data, at)
            if data[at + 9:at + 12] != b"\0\0\0" or codec > 1 or (codec == 0 and stored != raw):
                self._fail(f"block {b}'s table entry is malformed (codec {codec}, sizes {stored}/{raw})", at)
            least, most = block_bounds(c, m1, self.lossless, min(g, self.frames - b * g))
            if not least <= raw <= most or (codec == 1 and raw > 65536 * stored):
                self._fail(f"block {b} declares {raw:,} bytes, where its frames take {least:,} to {most:,}", at,
                           LimitError)
            blocks.append((start, stored, raw, codec))
            start += stored
            if start > len(data):
                self._fail(f"block {b} ends at byte {start:,}, past the chunk's {len(data):,}", at, LimitError)
        if start != len(data):
            self._fail(f"{len(data) - start} bytes follow the last block", start)
        return blocks

    def frame(self, t: int) -> Cards:
        """The cards at frame ``t`` (half-widths and groups the rest pose's)."""
        if not 0 <= t < self.frames:
            raise AssetError(f"frame {t} is outside the animation's 0..{self.frames - 1}")
        j = t % self.meta["keyframe_interval"]
        spine, normal = self._frames(t // self.meta["keyframe_interval"], slice(j, j + 1))
        return Cards(spine[0], normal[0], self.rest.half_width, self.rest.group)

    def animation(self) -> Animation:
        """Every frame."""
        self._check_bytes(self.frames, len(self._payload), "all")
        parts = [self._frames(b, slice(None)) for b in range(len(self._blocks))]
        return Animation(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]), self.fps,
                         self.start, self.meta["source"])

    def _frames(self, b: int, frames: slice) -> tuple[np.ndarray, np.ndarray]:
        """Spines and normals (float32) of block ``b``'s ``frames``. The last block read is kept as its
        integers (quantized: the floats of a frame are decoded when asked for, so that a player stepping
        through a block, or seeking into one, decodes one frame's cards a frame)."""
        if self._cache is None or self._cache[0] != b:
            self._cache = (b, self._decode_block(b))
        first, second = self._cache[1]
        if self.lossless:
            return first[frames], second[frames]
        try:
            return decode_quantized(first[frames], second[frames], self.meta["step"], self.meta["normal_bits"])
        except InvalidContentError as exc:
            self._fail(f"block {b}: {exc.message}", self._blocks[b][0])

    def _decode_block(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Block ``b``'s lossless spines and normals, or its integers ``Q`` and ``A`` (spec 4.6)."""
        start, stored, raw, codec = self._blocks[b]
        body = bytes(self._payload[start:start + stored])
        if codec == 1:
            body = _decompress(body, raw, lambda m: self._fail(m, start))
        g = self.meta["keyframe_interval"]
        n = min(g, self.frames - b * g)
        shape = (n, *self.rest.spine.shape)
        r = StreamReader(body, ANIM_CHUNK)
        try:
            if self.lossless:
                spine, normal = r.array(shape, "spine", ("<f4",)), r.array(shape, "normal", ("<f4",))
            else:
                spine_r, angle_r = r.ints(shape, "spine residuals"), r.ints(shape[:-1], "angle residuals")
            r.finish()
        except InvalidContentError as exc:  # (the block's own offset inside the chunk, then the file)
            self._fail(f"block {b}: {exc.message}", start, type(exc))
        if not self.lossless:
            return self._predicted(spine_r, angle_r)
        check = Animation(spine, normal, self.fps, self.start)
        try:
            check.validate(self.rest)
        except AssetError as exc:
            self._fail(f"block {b}: {exc}", start)
        if not (np.abs(spine) <= MAX_LENGTH).all():
            self._fail(f"block {b}: a spine lies beyond {MAX_LENGTH:g} scene units", start)
        return spine, normal

    def _predicted(self, spine_r: np.ndarray, angle_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Undo the predictions of one block (int64, wrapping; spec 4.6): its frames' integers ``Q``, ``A``."""
        bits = self.meta["normal_bits"]
        turn = 1 << bits
        with np.errstate(over="ignore"):
            e, turned = np.cumsum(spine_r, axis=2), np.cumsum(angle_r % turn, axis=2)  # along each card
            q, a = np.empty_like(e), np.empty_like(turned)
            q[0], a[0] = self._base + e[0], turned[0] % turn
            for j in range(1, len(q)):
                q[j] = (q[j - 1] if j == 1 else 2 * q[j - 1] - q[j - 2]) + e[j]
                a[j] = (a[j - 1] + turned[j]) % turn
        return q, a


def _decompress(body: bytes, raw: int, fail) -> bytes:
    """A block's zstd frame, held to ``raw`` bytes (spec 1.3 rule 6, as for a chunk)."""
    try:
        declared = zstandard.get_frame_parameters(body).content_size
        if declared not in (raw, zstandard.CONTENTSIZE_UNKNOWN):
            fail(f"a block's zstd frame declares {declared} bytes, the table {raw}")
        reader = zstandard.ZstdDecompressor().stream_reader(body, read_across_frames=True)
        out = reader.read(raw + 1) if raw else b""
        extra = reader.read(1)
    except zstandard.ZstdError as exc:
        fail(f"a block's zstd stream is corrupt: {exc}")
    if len(out) != raw or extra:
        fail(f"a block decompresses to {len(out) + len(extra)}{'+' if extra else ''} bytes, {raw} declared")
    return out


def animation_info(meta: dict, anim: container.ChunkInfo | None) -> dict | None:
    """What ``cgh info`` shows of a file's animation (None: it has none): META's ``animation`` object, the
    duration, ANIM's bytes a frame, and the bound of spec 4.6 (spine coordinates and normals' angles)."""
    if "animation" not in meta and anim is None:
        return None
    if ("animation" in meta) != (anim is not None):
        raise InvalidContentError("chunk ANIM must be present exactly when META has 'animation'",
                                  chunk=ANIM_CHUNK if anim is not None else "META")
    a = meta["animation"]
    bound = None if "step" not in a else {"spine": a["step"] / 2, "normal_radians": np.pi / 2 ** a["normal_bits"]}
    return a | {"duration": (a["frames"] - 1) / a["fps"], "stored_bytes": anim.stored,
                "bytes_per_frame": anim.stored / a["frames"], "bound": bound}
