""".cgh bytes -> HairAsset (spec: "Chunks"): META checked against its schema and the reader's limits
before any other chunk is decompressed, then each chunk's streams decoded.

Every refusal is a ``CghFormatError`` that names a chunk and a byte offset (where the decoder found no
finer place, the chunk's start in the file).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .. import container, memory
from ..animation.clip import Animation
from ..asset import Appearance, Cards, HairAsset, MlpLayer
from ..children import WEIGHT_ONE, place_children
from ..errors import AssetError, CghFormatError, InvalidContentError, LimitError, UnsupportedVersionError
from ..gaussians import Gaussians, decode_gaussians
from ..geometry import CardMap, angle_normals, card_scales
from ..limits import ReadLimits, default_limits
from ..limits import check as check_limits
from ..profiles import PROFILES
from ..quantize import hier_decode, level_plan, softmax_levels_decode, weights_decode
from ..residual_coder import read_residuals
from ..strand_coder import decode_uvd, level_widths, neighbour_decode, neighbour_order
from ..streams import StreamReader
from . import schema
from .animation import AnimationReader, animation_info
from .layout import (
    ANIM_CHUNK,
    ASSET_CHUNKS,
    COUNTS_CHUNK,
    FAMILY_CHUNK,
    KNOWN_CHUNKS,
    REQUIRED_CHUNKS,
    Family,
    prediction,
    uvd_scale,
)

Source = str | os.PathLike | bytes | bytearray | memoryview | BinaryIO


def read(source: Source, limits: ReadLimits | None = None) -> HairAsset:
    """Read a .cgh from a path, bytes or a binary file object; raises ``CghFormatError`` if bad, and
    ``LimitError`` (one) if it is larger than ``limits`` (default: :func:`.limits.default_limits`)."""
    return decode(read_bytes(source), limits)


def decode(data: bytes, limits: ReadLimits | None = None) -> HairAsset:
    return _decode(data, sh_ahead=False, limits=limits)[0]


def read_with_gaussians(source: Source, limits: ReadLimits | None = None) -> tuple[HairAsset, Gaussians]:
    """``read(source)`` and its ``decode_gaussians``, in one go and quicker: while a quantized file's
    strands decode, the kernel faults in the memory for their SH (hundreds of MB for a large asset;
    docs/compression.md, "Decode straight to Gaussians")."""
    asset, sh_out = _decode(read_bytes(source), sh_ahead=True, limits=limits)
    return asset, decode_gaussians(asset, sh_out)


def read_info(source: Source) -> dict:
    """What ``cgh info`` prints: header, chunk table and counts, without decoding the streams."""
    data = read_bytes(source)
    version, infos = container.verify(data, set(KNOWN_CHUNKS))
    meta_info = next((i for i in infos if i.type == "META"), None)
    if meta_info is None:
        raise InvalidContentError("required chunk 'META' is missing from the chunk table", chunk="META",
                                  offset=container.HEADER_SIZE)
    try:
        meta = schema.parse(meta_payload(data, meta_info))
    except CghFormatError as exc:
        raise exc.at(meta_info.offset) if exc.offset is None else exc from None
    counts_info = next((i for i in infos if i.type == COUNTS_CHUNK), None)
    if counts_info is not None and not meta["strands"] <= counts_info.raw <= 8 * meta["strands"] + 64:
        raise LimitError(f"PCNT's {counts_info.raw:,} bytes do not hold {meta['strands']:,} point counts",
                         chunk=COUNTS_CHUNK, offset=counts_info.offset)
    counts = (np.full(meta["strands"], meta["points"]) if counts_info is None else
              read_point_counts(container.payload(data, counts_info), meta["strands"], meta["points"]))
    gaussians = int((counts - 1).sum())
    if not meta["quant"]["lossless"] and meta["quant"].get("opacity_lowered", 0) > gaussians:
        raise InvalidContentError(f"META field 'quant.opacity_lowered' is out of range: "
                                  f"{meta['quant']['opacity_lowered']} (the file holds {gaussians:,} Gaussians)",
                                  chunk="META", offset=meta_info.offset)
    return {
        "version": f"{version[0]}.{version[1]}", "file_bytes": len(data), "profile": meta["profile"],
        "strands": meta["strands"], "points_per_strand": meta["points"], "gaussians": gaussians,
        "point_counts": [int(counts.min()), int(counts.max())],
        "cards": meta["cards"], "card_segments": meta["segments"], "groups": meta["groups"],
        "codebook_size": meta["k"], "latent_dim": meta["latent_dim"], "sh_degree": meta["sh_degree"],
        "weight_mode": meta["weight_mode"], "mlp": [layer["out"] for layer in meta["mlp"]],
        "thickness": meta["thickness"], "meters_per_unit": meta["meters_per_unit"], "up_axis": meta["up_axis"],
        "generator": meta["generator"], "attribution": meta["attribution"],
        "animation": _animation_info(meta, infos, meta_info.offset),
        "bits_per_gaussian": 8 * len(data) / gaussians, "quant": meta["quant"], "points_within": _points_within(meta),
        "opacities": _opacities(meta),
        "mlp_weights": _mlp_weights(meta, infos),
        "chunks": [{"type": i.type, "required": i.required, "codec": ["raw", "zstd"][i.codec],
                    "stored_bytes": i.stored, "raw_bytes": i.raw} for i in infos],
    }


def _mlp_weights(meta: dict, infos: list[container.ChunkInfo]) -> dict:
    """What the MLP costs: its weights and biases (a fixed cost, whatever the strand count) and MLPW's
    stored bytes and bits per value (None for a file without MLPW, which a decoder refuses)."""
    widths = [meta["latent_dim"]] + [layer["out"] for layer in meta["mlp"]]
    values = sum(i * o + o for i, o in zip(widths[:-1], widths[1:], strict=True))
    stored = next((i.stored for i in infos if i.type == "MLPW"), None)
    return {"values": values, "stored_bytes": stored, "bits_per_value": None if stored is None else 8 * stored / values}


def _animation_info(meta: dict, infos: list[container.ChunkInfo], meta_offset: int) -> dict | None:
    """:func:`.animation.animation_info`, its refusal placed at ANIM's start (or META's)."""
    anim = next((i for i in infos if i.type == ANIM_CHUNK), None)
    try:
        return animation_info(meta, anim)
    except CghFormatError as exc:
        raise exc.at(anim.offset if exc.chunk == ANIM_CHUNK else meta_offset) from None


def _points_within(meta: dict) -> float | None:
    """The strand points' bound as a fraction of the bbox diagonal (spec 7): 0 for lossless, META's
    ``quant.position_tolerance`` where recorded, else the named profile's (None: a profile this reader
    does not know)."""
    q = meta["quant"]
    if q["lossless"]:
        return 0.0
    known = PROFILES.get(meta["profile"])
    return q.get("position_tolerance", None if known is None else known.position_tolerance)


def _opacities(meta: dict) -> dict:
    """How near the file's opacities lie to the writer's input (spec 4.4): each within ``within`` (0:
    exact), but ``lowered`` of them (None: none; the file records it) more than that lower, down to 0,
    those of Gaussians that carry ``budget`` of the blend weight together (None: not recorded)."""
    q = meta["quant"]
    if q["lossless"]:
        return {"within": 0.0, "lowered": None, "budget": None}
    return {"within": 0.5 / q["opacity_scale"], "lowered": q.get("opacity_lowered"), "budget": q.get("opacity_budget")}


def animation_reader(source: Source, limits: ReadLimits | None = None) -> AnimationReader | None:
    """The animation of a .cgh (path, bytes or binary file object), ready to decode frame by frame
    (:meth:`AnimationReader.frame`), or None for a file without one. It decodes META and the rest cards
    only; the frames' blocks are checked against the file and META here, decoded when asked for."""
    data = read_bytes(source)
    infos: dict = {}
    try:
        _, table = container.verify(data, set(KNOWN_CHUNKS))
        infos = {i.type: i for i in table}
        for name in ("META", "CARD"):
            if name not in infos:
                raise InvalidContentError(f"required chunk {name!r} is missing from the chunk table", chunk=name,
                                          offset=container.HEADER_SIZE)
        meta = schema.parse(meta_payload(data, infos["META"]))
        anim = infos.get(ANIM_CHUNK)
        if "animation" not in meta and anim is None:
            return None
        if ("animation" in meta) != (anim is not None):
            raise InvalidContentError("chunk ANIM must be present exactly when META has 'animation'",
                                      chunk=ANIM_CHUNK if anim is not None else "META")
        if anim.codec != container.CODEC_RAW:
            raise InvalidContentError("chunk ANIM must be stored raw (codec 0): its blocks are compressed on "
                                      "their own", chunk=ANIM_CHUNK)
        limits = limits or default_limits()
        check_limits(meta, [infos["META"], infos["CARD"]], limits, False)
        card = StreamReader(container.payload(data, infos["CARD"]), "CARD")
        rest = read_cards(card, meta)
        return AnimationReader(meta, container.payload(data, anim), anim.offset, rest, limits)
    except CghFormatError as exc:
        if exc.offset is None and infos:
            raise exc.at(infos.get(exc.chunk, infos["META"]).offset) from None
        raise


def read_animation(source: Source, limits: ReadLimits | None = None) -> Animation | None:
    """Every frame of a .cgh's animation (None: the file has none); ``read(source)`` is its rest pose."""
    anim = animation_reader(source, limits)
    return None if anim is None else anim.animation()


def read_bytes(source: Source) -> bytes:
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source)
    if hasattr(source, "read"):
        data = source.read()
        if not isinstance(data, (bytes, bytearray)):
            raise TypeError("read() needs a binary file object (open the file with 'rb')")
        return bytes(data)
    return Path(source).read_bytes()


def _decode(data: bytes, sh_ahead: bool, limits: ReadLimits | None) -> tuple[HairAsset, np.ndarray | None]:
    """The asset, and with ``sh_ahead`` a quantized file's memory for :func:`.gaussians.strand_sh` (its
    ``out``), faulted in while the strands decode (else None)."""
    infos = {}
    try:
        version, table = container.verify(data, set(KNOWN_CHUNKS))
        infos = {i.type: i for i in table if i.type in ASSET_CHUNKS}  # (the animation's is read_animation's)
        for name in REQUIRED_CHUNKS:
            if name not in infos:
                raise InvalidContentError(f"required chunk {name!r} is missing from the chunk table", chunk=name,
                                          offset=container.HEADER_SIZE)
        meta = schema.parse(meta_payload(data, infos["META"]))
        if version[0] == 1 and not meta["quant"]["lossless"]:
            raise UnsupportedVersionError(
                f"format {version[0]}.{version[1]} quantized files decode with other arithmetic: rewrite it with "
                f"cghair 0.1 (cgh encode FILE -o LOSSLESS.cgh --profile lossless), then with this version "
                f"(cgh encode LOSSLESS.cgh -o NEW.cgh)", offset=8)
        check_limits(meta, list(infos.values()), limits or default_limits(), sh_ahead)
        payloads = {name: container.payload(data, info) for name, info in infos.items()}
        return _decode_payloads(meta, payloads, sh_ahead)
    except CghFormatError as exc:
        if exc.offset is None and infos:
            raise exc.at(infos.get(exc.chunk, infos["META"]).offset) from None
        raise


def meta_payload(data: bytes, info: container.ChunkInfo) -> bytes:
    """META's bytes, refused before decompressing when the chunk table gives it more than the limit."""
    if info.raw > schema.MAX_META_BYTES:
        raise LimitError(f"META of {info.raw} bytes exceeds {schema.MAX_META_BYTES}", chunk="META",
                         offset=info.offset)
    return container.payload(data, info)


# the chunk that stores each field HairAsset.validate() names first in its messages (else META's counts)
_ASSET_FIELD_CHUNKS = (("cards.", "CARD"), ("uvd", "STRD"), ("strand_card", "STRD"), ("opacity", "OPAC"),
                       ("appearance.logits", "LOGT"), ("appearance.codebooks", "CBKS"), ("codebooks", "CBKS"),
                       ("mlp[", "MLPW"), ("the MLP", "MLPW"), ("strand_ids", "SIDS"), ("root_uv", "ROOT"),
                       ("source_color", "SCOL"), ("point_counts", COUNTS_CHUNK))


def _decode_payloads(meta: dict, payloads: dict[str, bytes], sh_ahead: bool) -> tuple[HairAsset, np.ndarray | None]:
    children = 0 if meta["quant"]["lossless"] else meta["quant"].get("children", 0)
    if (FAMILY_CHUNK in payloads) != (children > 0):
        raise InvalidContentError(f"chunk {FAMILY_CHUNK} must be present exactly when META quant.children is "
                                  f"above 0 (quantized files only)", chunk=FAMILY_CHUNK)
    try:
        asset, sh_out = _decode_chunks(meta, payloads, sh_ahead)
        asset.validate()
    except AssetError as exc:
        chunk = next((c for prefix, c in _ASSET_FIELD_CHUNKS if str(exc).startswith(prefix)), "META")
        raise InvalidContentError(f"decoded contents are inconsistent: {exc}", chunk=chunk) from None
    return asset, sh_out


def _decode_chunks(meta: dict, payloads: dict[str, bytes], sh_ahead: bool) -> tuple[HairAsset, np.ndarray | None]:
    s, p, c = meta["strands"], meta["points"], meta["cards"]
    rd = {name: StreamReader(payloads[name], name) for name in REQUIRED_CHUNKS[1:]}
    strand_card = np.cumsum(rd["STRD"].ints((s,), "strand_card"))
    if strand_card.min() < 0 or strand_card.max() >= c:
        raise InvalidContentError(f"strand_card refers to cards outside [0, {c})", chunk="STRD")
    if meta["quant"]["lossless"]:
        (cards, uvd, opacity, appearance), sh_out = _decode_lossless(rd, meta), None
    else:
        cards, uvd, opacity, appearance, sh_out = _decode_quantized(rd, meta, strand_card, payloads.get(FAMILY_CHUNK),
                                                                    sh_ahead)
    for reader in rd.values():
        reader.finish()
    counts = None if COUNTS_CHUNK not in payloads else read_point_counts(payloads[COUNTS_CHUNK], s, p)
    asset = HairAsset(cards, strand_card.astype(np.int32), uvd, opacity.astype(np.float32), appearance,
                      float(meta["thickness"]), float(meta["meters_per_unit"]), meta["up_axis"], meta["generator"],
                      meta["attribution"], point_counts=counts)
    _decode_optional(asset, payloads, s, p)
    return asset, sh_out


def _decode_lossless(rd: dict[str, StreamReader], meta: dict) -> tuple[Cards, np.ndarray, np.ndarray, Appearance]:
    """Cards, card coordinates, opacities and appearance of a lossless file: float32 arrays as stored."""
    s, p, c, m, nt, k, d = (meta[key] for key in ("strands", "points", "cards", "segments", "groups", "k",
                                                    "latent_dim"))
    widths = [d] + [layer["out"] for layer in meta["mlp"]]
    f4 = ("<f4",)
    cards = read_cards(rd["CARD"], meta)
    uvd = rd["STRD"].array((s, p, 3), "uvd", f4)
    opacity = rd["OPAC"].array((s, p - 1), "opacity", f4)
    appearance = _appearance(meta, rd["LOGT"].array((s, k), "logits", f4),
                             rd["CBKS"].array((nt, k, d), "codebooks", f4),
                             [MlpLayer(rd["MLPW"].array((o, i), f"mlp[{j}].weight", f4),
                                       rd["MLPW"].array((o,), f"mlp[{j}].bias", f4), layer["activation"])
                              for j, (i, o, layer) in enumerate(zip(widths[:-1], widths[1:], meta["mlp"],
                                                                    strict=True))])
    return cards, uvd, opacity, appearance


def _decode_quantized(rd: dict[str, StreamReader], meta: dict, strand_card: np.ndarray, family_payload: bytes | None,
                      sh_ahead: bool) -> tuple[Cards, np.ndarray, np.ndarray, Appearance, np.ndarray | None]:
    """Cards, card coordinates, opacities and appearance of a quantized file, and with ``sh_ahead`` the
    SH's memory (see :func:`_decode`)."""
    s, p, q = meta["strands"], meta["points"], meta["quant"]
    cards = read_cards(rd["CARD"], meta)
    sh_out = None
    # the strand points (whose rANS decoder runs on one core) while the appearance streams decode and,
    # sh_ahead, the SH's memory faults in; a fault in STRD is raised first, as it comes first in the file
    with ThreadPoolExecutor(max_workers=1) as background:
        points = background.submit(_decode_strand_points, rd["STRD"], cards, strand_card, p, q, family_payload)
        try:
            opacity, *model = _decode_quantized_appearance(rd, meta, s, p, q)
            appearance = _appearance(meta, *model)
            if sh_ahead:  # filled once the strands are done, on every core
                appearance.validate(s, p - 1)
                sh_out = memory.empty((s, (p - 1) * appearance.sh_coeffs * 3), np.float32)
        except Exception:
            points.result()
            raise
        uvd = points.result()
    return cards, uvd, opacity, appearance, sh_out


def read_cards(r: StreamReader, meta: dict) -> Cards:
    """CARD's cards (spec 3, 4.2): float32 as stored (lossless) or decoded, then their groups."""
    c, m1 = meta["cards"], meta["segments"] + 1
    if meta["quant"]["lossless"]:
        f4 = ("<f4",)
        cards = Cards(r.array((c, m1, 3), "spine", f4), r.array((c, m1, 3), "normal", f4),
                      r.array((c, m1), "half_width", f4), np.zeros(c, np.int32))
    else:
        cards = decode_cards(r, c, m1, meta["quant"])
    cards.group = _read_groups(r, c)
    return cards


def get_hier(r: StreamReader, rows: int, n: int, base_stride: int, name: str) -> np.ndarray:
    """``[rows, n]`` values (step units) stored hierarchically (spec 4.1)."""
    base_idx, plan = level_plan(n, base_stride)
    base = r.ints((rows, len(base_idx)), f"{name} base")
    levels = [r.ints((rows, len(idx)), f"{name} level {i}") for i, (idx, _, _) in enumerate(plan)]
    return hier_decode(base, levels, n, base_stride)


def decode_cards(r: StreamReader, c: int, m1: int, q: dict) -> Cards:
    """The quantized cards' geometry; their groups (CARD's last array, :func:`_read_groups`) are left 0."""
    cq, s = q["card_step"], q["base_stride"]
    spine = get_hier(r, c * 3, m1, s, "spine").reshape(c, 3, m1).transpose(0, 2, 1) * cq
    normal = angle_normals(get_hier(r, c, m1, s, "normal angle"), spine, q["normal_bits"])
    half_width = np.maximum(get_hier(r, c, m1, s, "half_width") * cq, 0.0)
    return Cards(_float32(spine, "card spines", "CARD"), normal.astype(np.float32),
                 _float32(half_width, "card half-widths", "CARD"), np.zeros(c, np.int32))


def _float32(a: np.ndarray, what: str, chunk: str) -> np.ndarray:
    """``a`` as float32, or the error a corrupt step or residual stream deserves if it does not fit."""
    with np.errstate(over="raise"):
        try:
            return a.astype(np.float32)
        except FloatingPointError:
            raise InvalidContentError(f"{what} decode beyond float32's range (a corrupt step, scale or "
                                      f"residuals)", chunk=chunk) from None


def _read_groups(r: StreamReader, c: int) -> np.ndarray:
    """Each card's codebook group, CARD's last array."""
    return r.array((c,), "group", ("<u2", "<u4")).astype(np.int32)


def _appearance(meta: dict, logits: np.ndarray, codebooks: np.ndarray, mlp: list[MlpLayer]) -> Appearance:
    return Appearance(np.asarray(logits, np.float32), np.asarray(codebooks, np.float32), mlp, meta["sh_degree"],
                      meta["weight_mode"], float(meta["temperature"]))


def _decode_strand_points(r: StreamReader, cards: Cards, strand_card: np.ndarray, p: int, q: dict,
                          family_payload: bytes | None) -> np.ndarray:
    """The strands' card coordinates ``[S, p, 3]``: the guides' from STRD's residuals (after
    ``strand_card``), then the children's from CHLD (spec 4.5)."""
    g = len(strand_card) - q.get("children", 0)
    guide_card = strand_card[:g]
    columns = level_widths(p, q["base_stride"])
    residuals = read_residuals(r, guide_card, columns, q["neighbour_classes"])
    undo_neighbour_prediction(guide_card, residuals, columns, q["neighbour"])
    scale = uvd_scale(*card_scales(cards, q["step"]), guide_card, q["step"])
    cmap = CardMap(cards)
    uvd = decode_uvd(cmap, guide_card, residuals, p, scale, prediction(q))
    if family_payload is None:
        return uvd
    family = read_family(family_payload, g, len(strand_card) - g)
    card = strand_card.astype(np.int64)
    guides = cmap.strands(card[:g], uvd)
    try:
        children = place_children(cmap, q["step"], guides, family.parents, family.weights, family.respaced,
                                  card[g:])
    except ValueError as exc:
        raise InvalidContentError(f"{exc} (a corrupt step or weights)", chunk=FAMILY_CHUNK) from None
    return np.concatenate([uvd, children])


def read_point_counts(payload: bytes, s: int, p: int) -> np.ndarray:
    """PCNT (spec 3): each strand's own point count ``[S]`` (int32), each in 2..P and some below P."""
    r = StreamReader(payload, COUNTS_CHUNK)
    counts = r.ints((s,), "point counts")
    r.finish()
    if counts.min() < 2 or counts.max() > p:
        raise InvalidContentError(f"a strand's point count lies outside [2, {p}] (META points)", chunk=COUNTS_CHUNK)
    if counts.min() == p:
        raise InvalidContentError(f"every strand has all {p} points: the file must store no PCNT", chunk=COUNTS_CHUNK)
    return counts.astype(np.int32)


def undo_neighbour_prediction(strand_card: np.ndarray, values: np.ndarray, widths: list[int],
                              masks: list[int]) -> None:
    """Inverse of :func:`.chunks.with_neighbour_prediction`, in place, on the arrays side by side ``[S, N, 3]``."""
    order, starts = neighbour_order(strand_card)
    column_mask = np.repeat([[mask >> ch & 1 for ch in range(3)] for mask in masks], widths, axis=0)
    neighbour_decode(values, order, starts, column_mask)


def read_family(payload: bytes, guides: int, children: int) -> Family:
    """CHLD (spec 4.5; written by :func:`.chunks.family_payload`)."""
    r = StreamReader(payload, FAMILY_CHUNK)
    first = np.cumsum(r.ints((children,), "first parents"))
    parents = np.concatenate([first[:, None], first[:, None] + r.ints((children, 2), "other parents")], axis=1)
    second = r.ints((children, 2), "weights")
    respaced = r.array((children,), "resampled", ("|u1",))
    r.finish()
    if respaced.size and respaced.max() > 1:
        raise InvalidContentError("a child's resampling flag is neither 0 nor 1", chunk=FAMILY_CHUNK)
    if parents.size and (parents.min() < 0 or parents.max() >= guides):
        raise InvalidContentError(f"a child's parent lies outside the {guides} guide strands", chunk=FAMILY_CHUNK)
    if second.size and np.abs(second).max() > 2 * WEIGHT_ONE:
        raise InvalidContentError(f"a child's weight lies outside [-2, 2] (in units of 1/{WEIGHT_ONE})",
                                  chunk=FAMILY_CHUNK)
    weights = np.concatenate([WEIGHT_ONE - second.sum(1, keepdims=True), second], axis=1)
    return Family(guides, parents.astype(np.int64), weights.astype(np.int64), respaced.astype(bool))


def _decode_quantized_appearance(rd: dict[str, StreamReader], meta: dict, s: int, p: int, q: dict
                                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[MlpLayer]]:
    """Opacities, logits, codebooks and MLP layers of a quantized file."""
    nt, k, d = meta["groups"], meta["k"], meta["latent_dim"]
    widths = [d] + [layer["out"] for layer in meta["mlp"]]
    opacity = np.clip(get_hier(rd["OPAC"], s, p - 1, q["base_stride"], "opacity") / q["opacity_scale"], 0, 1)
    if meta["weight_mode"] == "hard":
        idx = rd["LOGT"].ints((s,), "assignment")
        if idx.min() < 0 or idx.max() >= k:
            raise InvalidContentError(f"codebook assignment outside [0, {k})", chunk="LOGT")
        logits = np.full((s, k), q["logit_floor"], np.float32)
        logits[np.arange(s), idx] = 0.0
    else:
        top = rd["LOGT"].array((s,), "largest logit", ("|u1", "<u2")).astype(np.int64)
        others = rd["LOGT"].array((s, k - 1), "other logits", ("|u1", "<u2", "<u4")).astype(np.int64)
        if top.size and (top.min() < 0 or top.max() >= k):
            raise InvalidContentError(f"largest logit's index outside [0, {k})", chunk="LOGT")
        if others.size and (others.min() < 0 or others.max() > q["logit_levels"]):
            raise InvalidContentError(f"soft logits outside [0, {q['logit_levels']}]", chunk="LOGT")
        levels = np.full((s, k), q["logit_levels"], np.int64)
        levels[np.arange(k)[None, :] != top[:, None]] = others.ravel()
        logits = softmax_levels_decode(levels, meta["temperature"], q["logit_levels"], q["logit_floor"])
    qc = rd["CBKS"].ints((nt, k, d), "codebooks")
    coded = [(rd["MLPW"].ints((o, i), f"mlp[{j}].weight"), rd["MLPW"].ints((o,), f"mlp[{j}].bias"))
             for j, (i, o) in enumerate(zip(widths[:-1], widths[1:], strict=True))]
    codebooks, layers = weights_decode(q["weight_steps"], qc, coded)
    mlp = [MlpLayer(w, b, layer["activation"]) for (w, b), layer in zip(layers, meta["mlp"], strict=True)]
    return opacity, logits, codebooks, mlp


def _decode_optional(asset: HairAsset, payloads: dict[str, bytes], s: int, p: int) -> None:
    if "SIDS" in payloads:
        r = StreamReader(payloads["SIDS"], "SIDS")
        ids = np.cumsum(r.ints((s,), "strand_ids"))
        r.finish()
        if ids.min() < 0 or ids.max() >= 1 << 32:
            raise InvalidContentError("strand ids outside the u32 range", chunk="SIDS")
        asset.strand_ids = ids.astype(np.uint32)
    if "ROOT" in payloads:
        r = StreamReader(payloads["ROOT"], "ROOT")
        asset.root_uv = r.array((s, 2), "root_uv", ("<f4",))
        r.finish()
    if "SCOL" in payloads:
        r = StreamReader(payloads["SCOL"], "SCOL")
        asset.source_color = r.array((s, p, 3), "source_color", ("|u1",)).astype(np.float32) / 255
        r.finish()
    if "XMET" in payloads:
        try:
            asset.metadata = schema.load_json(payloads["XMET"])
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise InvalidContentError(f"XMET is not valid UTF-8 JSON: {exc}", chunk="XMET") from None
        if not isinstance(asset.metadata, dict):
            raise InvalidContentError("XMET must be a JSON object", chunk="XMET")
