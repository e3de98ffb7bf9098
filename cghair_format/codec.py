"""HairAsset <-> .cgh bytes (spec: "Chunks"): quantized streams per profile, verified on write.

``write``/``read`` are the public entry points; ``encode``/``decode`` work on bytes.
"""

from __future__ import annotations

import json
import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import BinaryIO, NamedTuple

import numpy as np

from . import container, memory, rans
from .asset import ACTIVATIONS, MAX_LENGTH, UP_AXES, WEIGHT_MODES, Appearance, Cards, HairAsset, MlpLayer
from .atomic import write_bytes
from .children import (
    WEIGHT_ONE,
    Children,
    best_weights,
    find_children,
    fit_weights,
    place_children,
)
from .errors import AssetError, CghFormatError, InvalidContentError, LimitError, UnsupportedVersionError
from .gaussians import Gaussians, decode_gaussians
from .geometry import (
    CardMap,
    angle_normals,
    bounding_diagonal,
    card_scales,
    lengths,
    normal_angles,
    strand_points,
)
from .limits import ReadLimits, default_limits
from .limits import check as check_limits
from .parallel import map_blocks, map_threads
from .profiles import Profile, get_profile
from .quantize import (
    TAPS,
    hier_decode,
    hier_encode,
    level_plan,
    softmax_levels_decode,
    softmax_levels_encode,
    weight_steps,
    weights_decode,
    weights_encode,
)
from .residual_coder import (
    MAX_NEIGHBOUR_CLASSES,
    NEIGHBOUR_CLASSES,
    coded_bytes,
    read_residuals,
    write_residuals,
)
from .strand_coder import (
    NEWTON_HALVINGS,
    NEWTON_STEPS,
    STRETCH_MAX,
    Coded,
    DeadZone,
    Prediction,
    base_residuals,
    canonical_order,
    coded_uvd,
    decode_uvd,
    encode_uvd,
    level_widths,
    neighbour_decode,
    neighbour_encode,
    neighbour_order,
)
from .streams import StreamReader, StreamWriter

REQUIRED_CHUNKS = ("META", "CARD", "STRD", "OPAC", "LOGT", "CBKS", "MLPW")
OPTIONAL_CHUNKS = ("SIDS", "ROOT", "SCOL", "XMET")
FAMILY_CHUNK = "CHLD"  # required where META quant.children > 0 (spec 4.5), absent otherwise
MIN_CHILD_SHARE = 0.1  # interpolated strands are stored where at least this share of the strands are (below
# it the guides' chains lose more than the few children save; COMPRESSION.md, "Interpolated strands")
KNOWN_CHUNKS = frozenset(REQUIRED_CHUNKS + OPTIONAL_CHUNKS + (FAMILY_CHUNK,))
LIMITS = {"strands": 1 << 24, "points": 4096, "cards": 1 << 20, "segments": 1024, "groups": 1 << 16,
          "k": 256, "latent_dim": 4096, "mlp_layers": 16, "mlp_width": 1 << 20, "meta_bytes": 1 << 20}
CARD_STEP_FRACTION = 4  # card geometry is quantized this much coarser than strand points (which are coded
# on the quantized cards, so the cards' error does not reach them) ...
CARD_MISS_SHARE = 0.25  # ... and finer (halved) while some point has no card coordinates within this x tol
MIN_CARD_STEP_FRACTION = 1 / 1024  # on them (a coarse card can fold or lose its width)
MAX_TIGHTENINGS = 8
STEP_START = 1.0  # first step, as a fraction of the position tolerance
TIGHTEN_TARGET = 0.97  # a retry aims the measured error at this fraction of the tolerance ...
GROW_BELOW = 0.9  # ... and a first step whose error is below this fraction is retried larger, once
NUDGE, NUDGE_RARE = 0.99, 100_000  # where one point, or one in NUDGE_RARE, misses the tolerance, the step is
# first made 1 % smaller instead: the lattices align anew, and isolated misses seldom recur, while shrinking
# the step with the error would cost the whole file for one point (COMPRESSION.md, "The writer's per-file choices")
DEAD_ZONE = 0.97  # a refinement residual stays zero where the prediction is this close to the input (x tol)
BASE_SAMPLE_CARDS = 100  # the base stride and guide are chosen on this many cards


@dataclass
class EncodeReport:
    profile: str
    step: float | None  # strand-point quantization step (scene units), None if lossless
    max_point_error: float  # largest Euclidean distance to the input point, measured, scene units
    bbox_diagonal: float
    chunk_sizes: dict[str, int] = field(default_factory=dict)  # stored bytes per chunk
    # the file's strand i is the input's strand_order[i] (None: the input's order, kept)
    strand_order: np.ndarray | None = None

    def in_file_order(self, asset: HairAsset) -> HairAsset:
        """The encoded ``asset`` with its strands in the order the file stores them."""
        return asset if self.strand_order is None else asset.take_strands(self.strand_order)

    def strands_in_file_order(self, per_strand: np.ndarray) -> np.ndarray:
        """A per-strand array of the input (``[S, ...]``, such as its points) in the file's strand order."""
        return per_strand if self.strand_order is None else per_strand[self.strand_order]


# --- public API ----------------------------------------------------------------------------------

def write(asset: HairAsset, path: str | os.PathLike, profile: str | Profile = "compact",
          keep_order: bool = False) -> EncodeReport:
    """Write ``asset`` to ``path`` atomically (:mod:`.atomic`); see :func:`encode`."""
    data, report = encode(asset, profile, keep_order)
    write_bytes(path, data)
    return report


def read(source: str | os.PathLike | bytes | bytearray | memoryview | BinaryIO,
         limits: ReadLimits | None = None) -> HairAsset:
    """Read a .cgh from a path, bytes or a binary file object; raises ``CghFormatError`` if bad, and
    ``LimitError`` (one) if it is larger than ``limits`` (default: :func:`.limits.default_limits`)."""
    return decode(_read_bytes(source), limits)


def _read_bytes(source) -> bytes:
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source)
    if hasattr(source, "read"):
        data = source.read()
        if not isinstance(data, (bytes, bytearray)):
            raise TypeError("read() needs a binary file object (open the file with 'rb')")
        return bytes(data)
    return Path(source).read_bytes()


def encode(asset: HairAsset, profile: str | Profile = "compact", keep_order: bool = False
           ) -> tuple[bytes, EncodeReport]:
    """Serialise a validated asset; returns the bytes and what the quantization measured.

    The quantized profiles store the strands card by card, alike strands one after another (spec 4.3),
    and strands that blend others last, as children of those (4.5), which codes smaller:
    ``report.strand_order`` maps them back to the input's (the asset's optional per-strand data travel
    with their strands). ``keep_order`` keeps the input's order instead, and stores no children, at a
    cost; the lossless profile always keeps it. The encoder's arrays, short-lived, do without huge pages
    (:func:`.memory.without_huge_pages`)."""
    with memory.without_huge_pages():
        return _encode(asset, get_profile(profile), keep_order)


def _encode(asset: HairAsset, prof: Profile, keep_order: bool) -> tuple[bytes, EncodeReport]:
    asset.validate()
    points = strand_points(asset.cards, asset.strand_card, asset.uvd)
    diag = bounding_diagonal(points)
    points = points.astype(np.float64)
    tol = prof.position_tolerance * max(diag, 1e-12)
    reorder = not prof.lossless and not keep_order
    input_asset, input_points = asset, points
    kids = find_children(points, tol) if reorder else None
    if kids is not None and np.count_nonzero(kids.child) < MIN_CHILD_SHARE * len(points):
        kids = None  # a few children cost their guides more than they save
    arranged = _arrange(input_asset, input_points, kids) if reorder else (asset, points, None, None)
    # the largest point error is typically about 1.0 step (half a step on each of u, v, delta): start
    # where it usually meets the bound at once, then tighten or grow
    step = None if prof.lossless else STEP_START * tol
    passed = None  # (step, error, quantized geometry, arrangement) of the largest step that met the bound so far
    choices, nudged = None, False
    for attempt in range(MAX_TIGHTENINGS):
        asset, points, order, family = arranged
        geometry = _quantize_geometry(asset, prof, step, diag, points, tol, choices, family)
        choices = geometry.choices
        dist = _distances(geometry, points)
        if family is not None and (dist[family.guides:] > tol).any():
            # children that the decoded guides place too far become guides, last on their cards (the
            # guides before them decode as they did, so the other children stay where they were)
            late = np.zeros(len(input_points), bool)
            late[order[family.guides:][(dist[family.guides:] > tol).any(axis=1)]] = True
            before = order
            asset, points, order, family = _arrange(input_asset, input_points, kids, late, order[:family.guides])
            geometry = _with_late_guides(geometry, before, order, family.guides, asset, points)
            dist = _distances(geometry, points)
        err = float(dist.max())
        if step is None:
            passed = (step, err, geometry, (asset, order))
            break
        if err <= tol:
            passed = (step, err, geometry, (asset, order))
            if attempt > 0 or err >= GROW_BELOW * tol:
                break  # only a first step well inside the bound is retried larger
        elif passed is not None:
            break
        if err > tol and not nudged and np.count_nonzero(dist > tol) <= max(1, dist.size // NUDGE_RARE):
            step, nudged = step * NUDGE, True
        else:
            step *= TIGHTEN_TARGET * tol / err if err > 0 else 1 / GROW_BELOW
    if passed is None:
        raise AssetError(f"could not meet the position tolerance {tol:g} (error {err:g})")
    step, err, geometry, (asset, order) = passed
    level, quant = prof.zstd_level, dict(geometry.meta["quant"])
    with ThreadPoolExecutor(max_workers=1) as background:  # zstd on the appearance while STRD is coded
        appearance = background.submit(lambda: [container.compress(c, level)
                                                for c in _appearance_chunks(asset, prof, quant)])
        stored = map_threads(lambda c: container.compress(c, level), _geometry_chunks(asset, geometry))
        data = container.assemble(stored + appearance.result())
    _, infos = container.read_table(data)
    return data, EncodeReport(prof.name, step, err, diag, {i.type: i.stored for i in infos}, order)


def decode(data: bytes, limits: ReadLimits | None = None) -> HairAsset:
    return _decode(data, sh_ahead=False, limits=limits)[0]


def read_with_gaussians(source: str | os.PathLike | bytes | bytearray | memoryview | BinaryIO,
                        limits: ReadLimits | None = None) -> tuple[HairAsset, Gaussians]:
    """``read(source)`` and its ``decode_gaussians``, in one go and quicker: while a quantized file's
    strands decode, the kernel faults in the memory for their SH (hundreds of MB for a large asset;
    COMPRESSION.md, "Decode straight to Gaussians")."""
    asset, sh_out = _decode(_read_bytes(source), sh_ahead=True, limits=limits)
    return asset, decode_gaussians(asset, sh_out)


def _decode(data: bytes, sh_ahead: bool, limits: ReadLimits | None) -> tuple[HairAsset, np.ndarray | None]:
    """The asset, and with ``sh_ahead`` a quantized file's memory for :func:`.gaussians.strand_sh` (its
    ``out``), faulted in while the strands decode (else None). A refusal names a chunk and a byte offset
    (where the decoder found no finer place, the chunk's start in the file)."""
    infos = {}
    try:
        version, table = container.verify(data, set(KNOWN_CHUNKS))
        infos = {i.type: i for i in table if i.type in KNOWN_CHUNKS}
        for name in REQUIRED_CHUNKS:
            if name not in infos:
                raise InvalidContentError(f"required chunk {name!r} is missing from the chunk table", chunk=name,
                                          offset=container.HEADER_SIZE)
        meta = _parse_meta(_meta_payload(data, infos["META"]))
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


# the chunk that stores each field HairAsset.validate() names first in its messages (else META's counts)
_ASSET_FIELD_CHUNKS = (("cards.", "CARD"), ("uvd", "STRD"), ("strand_card", "STRD"), ("opacity", "OPAC"),
                       ("appearance.logits", "LOGT"), ("appearance.codebooks", "CBKS"), ("codebooks", "CBKS"),
                       ("mlp[", "MLPW"), ("the MLP", "MLPW"), ("strand_ids", "SIDS"), ("root_uv", "ROOT"),
                       ("source_color", "SCOL"))


# --- META ----------------------------------------------------------------------------------------

def _distances(geometry: _Geometry, points: np.ndarray) -> np.ndarray:
    """How far each point a decoder gets lies from the input's ``points`` (``[S, P]``; lossless: 0)."""
    decoded = geometry.decoded_points
    return np.zeros((1, 1)) if decoded is None else lengths(decoded - points)


def _meta(asset: HairAsset, prof: Profile, step: float | None, diag: float) -> dict:
    app = asset.appearance
    return {
        "strands": asset.n_strands, "points": asset.points_per_strand, "cards": asset.cards.count,
        "segments": asset.cards.segments, "groups": app.n_groups, "k": app.k, "latent_dim": app.latent_dim,
        "sh_degree": app.sh_degree, "weight_mode": app.weight_mode, "temperature": float(app.temperature),
        "mlp": [{"out": int(layer.weight.shape[0]), "activation": layer.activation} for layer in app.mlp],
        "thickness": float(asset.thickness), "meters_per_unit": float(asset.meters_per_unit),
        "up_axis": asset.up_axis, "generator": asset.generator, "attribution": asset.attribution,
        "bbox_diagonal": diag, "profile": prof.name,
        "quant": {"lossless": True} if step is None else {
            "lossless": False, "step": step, "card_step": step * CARD_STEP_FRACTION,
            "normal_bits": _normal_bits(asset, prof), "base_stride": prof.base_strides[0],
            "newton_halvings": NEWTON_HALVINGS, "stretch_max": STRETCH_MAX,
            # the writer's choices (_Choices) replace these five in _quantize_geometry
            "base_order": None, "base_guide": None, "newton_steps": None, "level_taps": None, "level_guide": None,
            "opacity_scale": prof.opacity_scale, "logit_levels": prof.logit_levels, "logit_floor": prof.logit_floor,
            "weight_steps": weight_steps(app.codebooks, [(x.weight, x.bias) for x in app.mlp], prof.weight_step)},
    }


def _normal_bits(asset: HairAsset, prof: Profile) -> int:
    """The profile's bits for the card normals' angles, or more where points lie so far off their card
    that the normals' error (at most pi / 2^bits rad, bounded here by 4 / 2^bits, times the distance)
    would reach a quarter of the shortest card segment: a step in ``u`` would then move such a point
    far more than the strip does, and no step would meet the tolerance."""
    seg = np.linalg.norm(np.diff(asset.cards.spine.astype(np.float64), axis=1), axis=-1).min(axis=1)
    far = np.zeros(asset.cards.count)
    np.maximum.at(far, asset.strand_card, np.abs(asset.uvd[..., 2]).max(axis=1))
    need = float(np.max(8 * far / np.maximum(seg, 1e-30), initial=0.0))
    return int(np.clip(math.ceil(math.log2(max(need, 1.0))) + 1, prof.normal_bits, 24))


def _meta_payload(data: bytes, info: container.ChunkInfo) -> bytes:
    """META's bytes, refused before decompressing when the chunk table gives it more than the limit."""
    if info.raw > LIMITS["meta_bytes"]:
        raise LimitError(f"META of {info.raw} bytes exceeds {LIMITS['meta_bytes']}", chunk="META", offset=info.offset)
    return container.payload(data, info)


def load_json(raw: bytes):
    """JSON from UTF-8 bytes with only finite numbers in float64's range (``ValueError`` otherwise), so that
    no field escapes as an ``OverflowError`` or a NaN later."""
    def number(text: str) -> float:
        v = float(text)
        if not math.isfinite(v):
            raise ValueError(f"number {text[:40]} is out of range")
        return v

    def integer(text: str) -> int:
        if len(text.lstrip("-")) > 18:
            raise ValueError(f"integer {text[:40]} is out of range")
        return int(text)

    def constant(text: str):
        raise ValueError(f"{text} is not a JSON number")

    return json.loads(raw.decode("utf-8"), parse_float=number, parse_int=integer, parse_constant=constant)


def _parse_meta(raw: bytes) -> dict:
    if len(raw) > LIMITS["meta_bytes"]:
        raise LimitError(f"META of {len(raw)} bytes exceeds {LIMITS['meta_bytes']}", chunk="META")
    try:
        meta = load_json(raw)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InvalidContentError(f"META is not valid UTF-8 JSON: {exc}", chunk="META") from None
    if not isinstance(meta, dict):
        raise InvalidContentError("META must be a JSON object", chunk="META")

    def need(key, kind, lo=None, hi=None, src=meta):
        v = src.get(key)
        ok = isinstance(v, kind) and not isinstance(v, bool) if kind is not bool else isinstance(v, bool)
        if ok and isinstance(v, float) and not math.isfinite(v):
            ok = False
        if not ok or (lo is not None and v < lo) or (hi is not None and v > hi):
            raise InvalidContentError(f"META field {key!r} is missing or out of range: {v!r}", chunk="META")
        return v

    for key, lo in (("strands", 1), ("points", 2), ("cards", 1), ("segments", 1), ("groups", 1),
                    ("k", 1), ("latent_dim", 1)):
        need(key, int, lo, LIMITS[key])
    need("sh_degree", int, 0, 3)
    if meta.get("weight_mode") not in WEIGHT_MODES or meta.get("up_axis") not in UP_AXES:
        raise InvalidContentError("META weight_mode or up_axis has an unknown value", chunk="META")
    need("temperature", (int, float), 1e-30)
    need("meters_per_unit", (int, float), 1e-30)
    need("thickness", (int, float), 1e-30, MAX_LENGTH)
    for key in ("generator", "attribution", "profile"):
        need(key, str)
    layers = meta.get("mlp")
    if not isinstance(layers, list) or not 1 <= len(layers) <= LIMITS["mlp_layers"]:
        raise InvalidContentError("META mlp must list 1 to 16 layers", chunk="META")
    for layer in layers:
        if not isinstance(layer, dict) or layer.get("activation") not in ACTIVATIONS:
            raise InvalidContentError("META mlp layer needs an activation of relu or none", chunk="META")
        need("out", int, 1, LIMITS["mlp_width"], src=layer)
    sh_values = (meta["points"] - 1) * (meta["sh_degree"] + 1) ** 2 * 3
    if layers[-1]["out"] != sh_values:  # the quantized last layer's rows are colour triples (spec 4.4)
        raise InvalidContentError(f"META mlp's last layer must output (points - 1) x (sh_degree + 1)^2 x 3 = "
                                  f"{sh_values} values, got {layers[-1]['out']}", chunk="META")
    quant = meta.get("quant")
    if not isinstance(quant, dict):
        raise InvalidContentError("META quant must be an object", chunk="META")
    if ("logit_step" in quant and "logit_levels" not in quant) or (
            quant.get("lossless") is False and any(key not in quant for key in (
                "newton_halvings", "stretch_max", "neighbour_classes", "base_guide", "weight_steps", "level_guide"))):
        raise InvalidContentError("written by a pre-release draft of .cgh 1.0 (before the rANS strand coder, "
                                  "searched Newton steps, stretched residual steps, neighbour token contexts, "
                                  "guided base samples, weights on steps, card normals as angles or level "
                                  "references), which this reader cannot decode: write the asset again from its "
                                  "source (cgh encode, or cgh train --resume CHECKPOINT)", chunk="META")
    if not need("lossless", bool, src=quant):
        for key in ("step", "card_step"):
            need(key, (int, float), 1e-30, MAX_LENGTH, src=quant)
        need("opacity_scale", (int, float), 1e-30, src=quant)
        need("logit_levels", int, 1, 1 << 24, src=quant)
        need("logit_floor", (int, float), -1e6, 0, src=quant)
        need("normal_bits", int, 8, 24, src=quant)
        if need("base_stride", int, 1, 256, src=quant) & (quant["base_stride"] - 1):
            raise InvalidContentError(f"META quant.base_stride must be a power of two, got {quant['base_stride']}",
                                      chunk="META")
        need("newton_steps", int, 0, 8, src=quant)
        need("newton_halvings", int, 0, 8, src=quant)
        need("stretch_max", (int, float), 1, 16, src=quant)
        need("neighbour_classes", int, 1, MAX_NEIGHBOUR_CLASSES, src=quant)
        need("base_guide", int, 0, 3, src=quant)
        need("level_guide", int, 0, 1, src=quant)
        if "children" in quant:
            need("children", int, 0, meta["strands"] - 1, src=quant)
        orders = quant.get("base_order")
        if (not isinstance(orders, list) or len(orders) != 3
                or not all(isinstance(k, int) and not isinstance(k, bool) and k in (1, 2) for k in orders)):
            raise InvalidContentError(f"META quant.base_order must list 3 orders (u, v, delta), each 1 or 2, got "
                                      f"{orders!r}", chunk="META")
        steps = quant.get("weight_steps")
        if (not isinstance(steps, list) or len(steps) != len(layers) + 1
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x > 0
                           for x in steps)):
            raise InvalidContentError(f"META quant.weight_steps must list {len(layers) + 1} positive steps (the "
                                      f"codebooks', then each MLP layer's), got {steps!r}", chunk="META")
        arrays = 1 + len(level_plan(meta["points"], quant["base_stride"])[1])
        taps = quant.get("level_taps")
        if (not isinstance(taps, list) or len(taps) != arrays - 1
                or not all(isinstance(t, int) and not isinstance(t, bool) and t in TAPS for t in taps)):
            raise InvalidContentError(f"META quant.level_taps must list {arrays - 1} interpolation widths, each one of "
                                      f"{', '.join(map(str, TAPS))}, got {taps!r}", chunk="META")
        masks = quant.get("neighbour")
        if (not isinstance(masks, list) or len(masks) != arrays
                or not all(isinstance(m, int) and not isinstance(m, bool) and 0 <= m <= 7 for m in masks)):
            raise InvalidContentError(f"META quant.neighbour must list {arrays} channel masks in 0..7, got "
                                      f"{masks!r}", chunk="META")
        if quant["level_guide"] and any(masks[1:]):
            raise InvalidContentError(f"META quant.neighbour must be 0 for the refinement levels with level_guide "
                                      f"(they are differences from their references' already), got {masks!r}",
                                      chunk="META")
    return meta


# --- chunks ---------------------------------------------------------------------------------------

class _Choices(NamedTuple):
    """The writer's per-file choices for the strand points, made on the first step it tries and kept
    for the others (they hardly depend on the step)."""

    base_stride: int
    base_order: tuple[int, int, int]
    newton_steps: int
    neighbour_zone: bool
    level_taps: tuple[int, ...]
    base_guide: int
    level_guide: bool


class _Geometry(NamedTuple):
    """What depends on the point step: META, the CARD streams, and (quantized profiles) the STRD
    residual arrays, the world points a decoder will get and the choices made."""

    meta: dict
    cards: StreamWriter
    residuals: list[np.ndarray] | None
    decoded_points: np.ndarray | None
    choices: _Choices | None
    family: _Family | None = None  # the interpolated strands, with their weights fitted to the decoded guides
    coding: _Coding | None = None  # with a family: what coding more guides after these takes


class _Coding(NamedTuple):
    """The strand coder's state with a family (:func:`_with_late_guides`): the quantized cards' map, the
    guides' input card coordinates on them (file order), the coder's state and the dead zone's reach."""

    cmap: CardMap
    cards: Cards
    card_uvd: np.ndarray
    state: Coded
    zone_distance: float


class _Family(NamedTuple):
    """The file's interpolated strands (spec 4.5): the first ``guides`` strands are coded in STRD, the
    rest are children of ``parents`` (indices among the guides) with ``weights``."""

    guides: int
    parents: np.ndarray  # [children, 3] int64
    weights: np.ndarray  # [children, 3] int64, summing to WEIGHT_ONE
    respaced: np.ndarray  # [children] bool: the blend resampled at even arc length


def _arrange(asset: HairAsset, points: np.ndarray, kids: Children | None, late: np.ndarray | None = None,
             chains: np.ndarray | None = None) -> tuple[HairAsset, np.ndarray, np.ndarray, _Family | None]:
    """The asset and its points in file order (spec 4.3, 4.5): the guides card by card in the writer's
    chains, then the ``late`` guides by card (children that the decoded guides placed too far: each
    ends its card's chain, so the guides before it decode as they did), then the children by their
    first parent; that order (indices into the input) and the family (None: no children). ``chains``:
    the guides' chains if known (:func:`canonical_order` of the strands not children)."""
    if kids is None or not kids.child.any():
        order = canonical_order(asset.cards, asset.strand_card, asset.uvd)
        return asset.take_strands(order), points[order], order, None
    late = np.zeros(len(kids.child), bool) if late is None else late
    guides = np.flatnonzero(~kids.child)
    if chains is None:
        chains = guides[canonical_order(asset.cards, asset.strand_card[guides], asset.uvd[guides])]
    guides, later = chains, np.flatnonzero(late)
    guides = np.concatenate([guides, later[np.argsort(asset.strand_card[later], kind="stable")]])
    children = np.flatnonzero(kids.child & ~late)
    at = np.full(len(kids.child), -1, np.int64)
    at[guides] = np.arange(len(guides))
    parents = at[kids.parents[children]]
    by_parent = np.lexsort((parents[:, 2], parents[:, 1], parents[:, 0]))
    order = np.concatenate([guides, children[by_parent]])
    family = _Family(len(guides), parents[by_parent], kids.weights[children[by_parent]],
                     kids.respaced[children[by_parent]])
    return asset.take_strands(order), points[order], order, family


def _quantize_geometry(asset: HairAsset, prof: Profile, step: float | None, diag: float, points: np.ndarray,
                       tol: float, choices: _Choices | None = None, family: _Family | None = None) -> _Geometry:
    """What depends on the step: META, the CARD streams, and (quantized profiles) the STRD residual
    arrays and the world points a decoder will get (``points``: the input's), with ``choices`` (None:
    made here). With a ``family`` STRD codes the guides, and the children are placed on the decoded
    ones (:func:`_place_family`)."""
    meta = _meta(asset, prof, step, diag)
    q = meta["quant"]
    cards_w = StreamWriter()
    if q["lossless"]:
        for a in (asset.cards.spine, asset.cards.normal, asset.cards.half_width):
            cards_w.array(a.astype(np.float32), shuffle=True)
        return _Geometry(meta, cards_w, None, None, None)
    coded = asset if family is None else asset.take_strands(np.arange(family.guides))
    zone = DeadZone(points[:coded.n_strands], DEAD_ZONE * prof.position_tolerance * diag)
    stride, guide = ((choices.base_stride, choices.base_guide) if choices is not None
                     else _choose_base_samples(coded, q, zone, prof.base_strides))
    q["base_stride"] = stride  # before the cards, whose coding takes it too
    strand_card = asset.strand_card
    asset = coded  # the children's card coordinates come from their parents (4.5)
    cards_w, cards, cmap, uvd = _quantized_cards(asset, q, points[:asset.n_strands], tol)
    scale = _uvd_scale(*card_scales(cards, q["step"]), asset.strand_card, q["step"])
    y = uvd * scale[:, None, :]
    if choices is None:
        base_order = _choose_base_order(asset.strand_card, y, stride)
        plan = Prediction(stride, base_order, NEWTON_STEPS, newton_halvings=q["newton_halvings"],
                          stretch_max=q["stretch_max"], base_guide=guide)
        plan = replace(plan, newton_steps=_choose_newton_steps(cmap, asset.strand_card, y, scale, plan))
        neighbour_zone = _choose_neighbour_zone(cmap, asset.strand_card, y, scale, plan, zone)
        zone = zone._replace(neighbour=neighbour_zone)
        plan = replace(plan, level_taps=_choose_level_taps(cmap, asset.strand_card, y, scale, plan, zone))
        choices = _Choices(stride, base_order, plan.newton_steps, neighbour_zone, plan.level_taps, guide,
                           _choose_level_guide(cmap, asset.strand_card, y, scale, plan, zone))
    q["base_order"], q["newton_steps"] = list(choices.base_order), choices.newton_steps
    q["level_taps"], q["base_guide"] = list(choices.level_taps), choices.base_guide
    q["level_guide"] = int(choices.level_guide)
    base, levels, decoded_points, state = encode_uvd(
        cmap, asset.strand_card, y, scale, _prediction(q), dead_zone=zone._replace(neighbour=choices.neighbour_zone),
        room=0 if family is None else len(points))
    if family is None:
        return _Geometry(meta, cards_w, [base] + levels, decoded_points, choices)
    q["children"] = len(family.parents)
    family, world = _place_family(cmap, q["step"], strand_card, coded_uvd(state, scale), family, points)
    return _Geometry(meta, cards_w, [base] + levels, world, choices, family,
                     _Coding(cmap, cards, uvd, state, zone.distance))


def _with_late_guides(geometry: _Geometry, before: np.ndarray, order: np.ndarray, guides: int, asset: HairAsset,
                      points: np.ndarray) -> _Geometry:
    """``geometry`` (of the file order ``before``) in the file order ``order`` (:func:`_arrange`; ``asset``
    and ``points`` in it), which makes the strands from its children up to ``guides`` guides, coded
    after the others, each last on its card (spec 4.5): only they are coded, the guides before them
    decode as they did, and the other children keep their weights and points."""
    family, coding = geometry.family, geometry.coding
    g0 = family.guides
    at = np.empty(len(before), np.int64)
    at[before] = np.arange(len(before))
    was = at[order]  # where each strand was in the geometry's file order
    kids = was[guides:]  # (the new guides, was[g0:guides], are coded below)
    meta = json.loads(json.dumps(geometry.meta))
    q = meta["quant"]
    q["children"] = len(kids)
    if not len(kids):
        del q["children"]  # (and no CHLD: every child became a guide)
    card = asset.strand_card[:guides]
    on_cards, _ = _on_cards(coding.cards, coding.cmap, card[g0:], asset.uvd[g0:guides], points[g0:guides],
                            1e-3 * q["step"])
    uvd = np.concatenate([coding.card_uvd, on_cards])
    scale = _uvd_scale(*card_scales(coding.cards, q["step"]), card, q["step"])
    zone = DeadZone(points[:guides], coding.zone_distance, geometry.choices.neighbour_zone)
    base, levels, _, state = encode_uvd(coding.cmap, card, uvd * scale[:, None, :], scale, _prediction(q),
                                        dead_zone=zone, before=coding.state)
    late_world = coding.cmap.strands(card[g0:], coded_uvd(state, scale, g0))
    world = np.concatenate([geometry.decoded_points[:g0], late_world.astype(np.float32).astype(np.float64),
                            geometry.decoded_points[kids]])
    kept = _Family(guides, family.parents[kids - g0], family.weights[kids - g0], family.respaced[kids - g0])
    return _Geometry(meta, geometry.cards, [base] + levels, world, geometry.choices, kept,
                     coding._replace(card_uvd=uvd, state=state))


def _place_family(cmap: CardMap, step: float, strand_card: np.ndarray, guides_uvd: np.ndarray, family: _Family,
                  points: np.ndarray) -> tuple[_Family, np.ndarray]:
    """The family with each child's weights refitted to the decoded guides (``guides_uvd``; ``points``,
    the input's in file order): the search's or a least-squares fit's, whichever places the child
    nearer its points; and the world points ``[S, P, 3]`` a decoder will get for every strand."""
    g = family.guides
    card = strand_card.astype(np.int64)
    guides = cmap.strands(card[:g], guides_uvd)
    kids = points[g:]
    weights, respaced, _ = best_weights(kids, guides, family.parents,
                                        [family.weights / WEIGHT_ONE, fit_weights(kids, guides, family.parents)])
    family = family._replace(weights=weights, respaced=respaced)
    world = cmap.strands(card[g:], place_children(cmap, step, guides, family.parents, weights, respaced, card[g:]))
    # as a reader gets them (float32, :func:`.geometry.strand_points`)
    return family, np.concatenate([guides, world]).astype(np.float32).astype(np.float64)


def _quantized_cards(asset: HairAsset, q: dict, points: np.ndarray, tol: float
                     ) -> tuple[StreamWriter, Cards, CardMap, np.ndarray]:
    """The CARD streams at ``q["card_step"]`` (halved, down to MIN_CARD_STEP_FRACTION of the point
    step, while some point is left more than CARD_MISS_SHARE x ``tol`` off), the cards a decoder will
    get, their map, and the input ``points``' card coordinates ``[S, P, 3]`` on them."""
    while True:
        cards_w = StreamWriter()
        cards = _encode_cards(asset.cards, q, cards_w)
        cmap = CardMap(cards)
        uvd, miss = _on_cards(cards, cmap, asset.strand_card, asset.uvd, points, 1e-3 * q["step"])
        if miss <= CARD_MISS_SHARE * tol or q["card_step"] <= MIN_CARD_STEP_FRACTION * q["step"]:
            return cards_w, cards, cmap, uvd
        q["card_step"] /= 2


def _on_cards(cards: Cards, cmap: CardMap, strand_card: np.ndarray, uvd: np.ndarray, points: np.ndarray,
              atol: float) -> tuple[np.ndarray, float]:
    """The card coordinates ``[S, P, 3]`` of the input ``points`` on the quantized ``cards`` (``cmap``
    their map), from their coordinates ``uvd`` on the input's cards, and the largest distance left
    between a point and its coordinates' image. The strand coder then codes the points themselves,
    and the cards' own quantization error does not add to theirs. Newton steps (compiled) solve
    nearly every point; the few they leave farther than ``atol`` off (off the strip, where the
    mapping folds) are solved exactly (:func:`.cards.inverse.solve_uvd`) where that is nearer."""
    from .cards.inverse import solve_uvd

    s, p = uvd.shape[:2]
    card = np.repeat(strand_card.astype(np.int64), p)
    flat_uvd, flat_points = uvd.reshape(-1, 3), points.reshape(-1, 3)
    out, miss = np.empty((s * p, 3)), np.empty(s * p)

    def block(b: slice) -> None:
        out[b], miss[b] = cmap.invert(card[b], flat_uvd[b], flat_points[b])

    map_blocks(block, s * p, 1 << 16)
    off = np.flatnonzero(miss > atol)
    if len(off):
        exact, _ = solve_uvd(cards, flat_points[off], card[off], out[off, 0] * cards.segments)
        exact_miss = np.linalg.norm(cmap(card[off], exact) - flat_points[off], axis=-1)
        nearer = exact_miss < miss[off]
        out[off[nearer]], miss[off[nearer]] = exact[nearer], exact_miss[nearer]
    return out.reshape(s, p, 3), float(miss.max(initial=0.0))


def _geometry_chunks(asset: HairAsset, geometry: _Geometry) -> list[container.Chunk]:
    """META, CARD and STRD once the step is settled: the residuals go through neighbour prediction
    and the entropy coder (lossless: the card coordinates as float32)."""
    meta, cards_w, residuals = geometry.meta, geometry.cards, geometry.residuals
    strd_w = StreamWriter()
    strd_w.ints(np.diff(asset.strand_card.astype(np.int64), prepend=0))
    if residuals is None:
        strd_w.array(asset.uvd.astype(np.float32), shuffle=True)
    else:
        coded = asset.strand_card[:len(residuals[0])]  # the guides, where there are children (spec 4.5)
        stored, meta["quant"]["neighbour"] = _with_neighbour_prediction(coded, residuals,
                                                                        bool(meta["quant"]["level_guide"]))
        meta["quant"]["neighbour_classes"] = write_residuals(strd_w, stored, coded, (NEIGHBOUR_CLASSES, 1))
    groups = asset.cards.group.astype(np.uint16 if asset.appearance.n_groups <= 65536 else np.uint32)
    cards_w.array(groups, shuffle=True)
    chunks = [container.Chunk("META", json.dumps(meta, separators=(",", ":")).encode("utf-8")),
              container.Chunk("CARD", cards_w.getvalue()), container.Chunk("STRD", strd_w.getvalue())]
    if geometry.family is not None and len(geometry.family.parents):
        chunks.append(container.Chunk(FAMILY_CHUNK, _family_payload(geometry.family)))
    return chunks


def _family_payload(family: _Family) -> bytes:
    """CHLD (spec 4.5): each child's first parent as the difference from the previous child's, its
    other parents as differences from its first, its second and third weights, and whether its blend
    is resampled at even arc length."""
    w = StreamWriter()
    first = family.parents[:, 0]
    w.ints(np.diff(first, prepend=0))
    w.ints(family.parents[:, 1:] - first[:, None])
    w.ints(family.weights[:, 1:])
    w.array(family.respaced.astype(np.uint8))
    return w.getvalue()


def _read_family(payload: bytes, guides: int, children: int) -> _Family:
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
    return _Family(guides, parents.astype(np.int64), weights.astype(np.int64), respaced.astype(bool))


def _appearance_chunks(asset: HairAsset, prof: Profile, quant: dict) -> list[container.Chunk]:
    """OPAC, LOGT, CBKS and MLPW, then the optional chunks: none depends on the point step (the
    opacities take the file's base stride, ``quant``)."""
    opac_w, logt_w, cbks_w, mlp_w = (StreamWriter() for _ in range(4))
    app = asset.appearance
    if prof.lossless:
        opac_w.array(asset.opacity.astype(np.float32), shuffle=True)
        logt_w.array(app.logits.astype(np.float32), shuffle=True)
        cbks_w.array(app.codebooks.astype(np.float32), shuffle=True)
        for layer in app.mlp:
            mlp_w.array(layer.weight.astype(np.float32), shuffle=True)
            mlp_w.array(layer.bias.astype(np.float32), shuffle=True)
    else:
        _put_hier(opac_w, asset.opacity * prof.opacity_scale, quant["base_stride"])
        if app.weight_mode == "hard":
            logt_w.ints(np.argmax(app.logits, axis=1))
        else:
            levels = softmax_levels_encode(app.logits, app.temperature, prof.logit_levels)
            top = np.argmax(levels, axis=1)  # its level is always logit_levels: store where, not what
            others = levels[np.arange(app.k)[None, :] != top[:, None]].reshape(len(levels), app.k - 1)
            logt_w.array(top.astype(_narrowest(app.k - 1)))
            logt_w.array(others.astype(_narrowest(prof.logit_levels)))
        qc, layers = weights_encode(quant["weight_steps"], app.codebooks, [(x.weight, x.bias) for x in app.mlp])
        cbks_w.ints(qc)
        for qw, qb in layers:
            mlp_w.ints(qw)
            mlp_w.ints(qb)
    chunks = [container.Chunk(t, w.getvalue()) for t, w in
              (("OPAC", opac_w), ("LOGT", logt_w), ("CBKS", cbks_w), ("MLPW", mlp_w))]
    return chunks + _optional_chunks(asset)


def _with_neighbour_prediction(strand_card: np.ndarray, residuals: list[np.ndarray], level_guide: bool = False
                               ) -> tuple[list[np.ndarray], list[int]]:
    """Per residual array and channel, the plain residuals or their differences from the card
    neighbour's (spec 4.3), whichever the entropy coder's estimate finds smaller. Returns the arrays
    to store and, per array, the mask of channels stored as differences (bit 0 u, bit 1 v, bit 2
    delta). With ``level_guide`` the levels are left as they are: differences from their references'
    already."""
    order, starts = neighbour_order(strand_card)
    stored, masks = [], []
    for a, r in enumerate(residuals):
        r = r.copy()
        mask = 0
        for ch in range(3) if a == 0 or not level_guide else ():
            diff = neighbour_encode(r[..., ch], order, starts)
            if _estimate(diff) < _estimate(r[..., ch]):
                r[..., ch] = diff
                mask |= 1 << ch
        stored.append(r)
        masks.append(mask)
    return stored, masks


def _undo_neighbour_prediction(strand_card: np.ndarray, values: np.ndarray, widths: list[int],
                               masks: list[int]) -> None:
    """Inverse of :func:`_with_neighbour_prediction`, in place, on the arrays side by side ``[S, N, 3]``."""
    order, starts = neighbour_order(strand_card)
    column_mask = np.repeat([[mask >> ch & 1 for ch in range(3)] for mask in masks], widths, axis=0)
    neighbour_decode(values, order, starts, column_mask)


def _narrowest(top: int) -> type:
    """The narrowest unsigned integer type that holds ``0 .. top``."""
    return next(t for t in (np.uint8, np.uint16, np.uint32) if top <= np.iinfo(t).max)


def _estimate(residuals: np.ndarray) -> float:
    """Bytes that STRD's entropy coder needs for these residuals, roughly: the writer's yardstick."""
    return rans.estimate_bytes(residuals)


def _prediction(q: dict) -> Prediction:
    return Prediction(q["base_stride"], tuple(q["base_order"]), q["newton_steps"], tuple(q["level_taps"]),
                      q["newton_halvings"], float(q["stretch_max"]), q["base_guide"], bool(q["level_guide"]))


def _choose_base_samples(asset: HairAsset, q: dict, zone: DeadZone, strides: tuple[int, ...]) -> tuple[int, int]:
    """The base stride (spec 4.1, 4.3) of ``strides`` (the profile's: 16 or 8) and the base samples'
    guide (0: none, 2: the card neighbour's steps scaled as the strands' previous steps compare, 3: the
    steps of the most alike earlier strand): of both guides at each stride and none at the first,
    whichever codes the strands of a sample of cards smallest (4-point interpolation, the dead zone
    trying the neighbour's residual; on the input's cards, before they are quantized at the stride
    chosen). Wavy strands want base samples closer together, straighter ones fewer, and straight
    strands of unequal lengths the scaled guide. The sample is coded with the neighbour's residual in
    the dead zone, as the file is: without it the sample can rank the strides the wrong way round
    (COMPRESSION.md, "The writer's per-file choices")."""
    cmap = CardMap(asset.cards)
    scale = _uvd_scale(*card_scales(asset.cards, q["step"]), asset.strand_card, q["step"])
    y = asset.uvd * scale[:, None, :]
    orders = dict(zip(strides, map_threads(lambda stride: _choose_base_order(asset.strand_card, y, stride),
                                           list(strides)), strict=True))
    tried = [(stride, guide) for stride in strides for guide in (2, 3)] + [(strides[0], 0)]

    def size(trial: tuple[int, int]) -> float:
        stride, guide = trial
        plan = Prediction(stride, orders[stride], NEWTON_STEPS, newton_halvings=q["newton_halvings"],
                          stretch_max=q["stretch_max"], base_guide=guide)
        return coded_bytes(_sample_residuals(cmap, asset.strand_card, y, scale, plan, zone._replace(neighbour=True),
                                             BASE_SAMPLE_CARDS))

    sizes = dict(zip(tried, map_threads(size, tried), strict=True))
    return min(sizes, key=sizes.get)


def _choose_base_order(strand_card: np.ndarray, y: np.ndarray, base_stride: int) -> tuple[int, int, int]:
    """Per channel (u, v, delta), the base samples' predictor, linear extrapolation (2) or the previous
    sample (1), whichever the coder's estimate finds smaller once neighbour prediction has had its
    say: strands of a card that run parallel share their steps more than their bends, which favours
    1; a strand advancing along its card at an even pace favours 2 for u."""
    base, _ = level_plan(y.shape[1], base_stride)
    order, starts = neighbour_order(strand_card)
    sizes = {}
    for k in (2, 1):
        r = base_residuals(y, base, (k, k, k))[:, 1:]
        sizes[k] = [min(_estimate(r[..., ch]), _estimate(neighbour_encode(r[..., ch], order, starts)))
                    for ch in range(3)]
    return tuple(1 if sizes[1][ch] < sizes[2][ch] else 2 for ch in range(3))


def _choose_newton_steps(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                         plan: Prediction, sample: int = 512) -> int:
    """World-guided prediction (``plan.newton_steps``) or plain card-space prediction (0), whichever
    codes an evenly spaced sample of strands smaller. Strands smooth in the world (real hair) favour
    the former; strands smooth on their card (procedural examples) the latter."""
    pick = np.linspace(0, len(strand_card) - 1, min(sample, len(strand_card))).astype(np.int64)
    sizes = {}
    for steps in (plan.newton_steps, 0):
        trial = replace(plan, newton_steps=steps)
        base, levels, *_ = encode_uvd(cmap, strand_card[pick], y[pick], scale[pick], trial)
        sizes[steps] = sum(_estimate(r) for r in [base] + levels)
    return min(sizes, key=sizes.get)


def _choose_neighbour_zone(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                           plan: Prediction, zone: DeadZone) -> bool:
    """Whether the dead zone first tries the card neighbour's residual: whichever codes the strands of
    a sample of cards smaller. It pays where a card's strands are much alike (strands densified from
    fewer) and costs a little where they are not (COMPRESSION.md, "Dead zone")."""
    tried = [True, False]
    sizes = map_threads(lambda neighbour: sum(map(_estimate, _sample_residuals(
        cmap, strand_card, y, scale, plan, zone._replace(neighbour=neighbour), 64))), tried)
    return tried[int(np.argmin(sizes))]


def _choose_level_taps(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                       plan: Prediction, zone: DeadZone) -> tuple[int, ...]:
    """Per refinement level, the interpolation width (2, 4 or 6; the format allows 8 too, which did
    not beat 6 on real hair) whose residuals the estimate finds smallest on the strands of a sample
    of cards, each width tried on every level at once; kept if the strand coder then codes that
    sample smaller than with 4 everywhere. Wavy strands want wide interpolation at the middle levels;
    the coarsest level, whose neighbours lie B points apart, is often best linear. The widths
    interact (the dead zone leaves a coarser level's reconstruction on its prediction, from which
    the finer levels predict) and the estimate ignores the coder's contexts, so close calls can come
    out the other way: hence the check (COMPRESSION.md, "The writer's per-file choices")."""
    levels = len(level_plan(y.shape[1], plan.base_stride)[1])
    widths = (2, 4, 6)
    trial = dict(zip(widths, map_threads(lambda t: _sample_residuals(
        cmap, strand_card, y, scale, replace(plan, level_taps=(t,) * levels), zone), list(widths)), strict=True))
    chosen = tuple(widths[k] for k in np.argmin([list(map(_estimate, trial[t][1:])) for t in widths], axis=0))
    if chosen == (4,) * levels:
        return chosen
    mixed = _sample_residuals(cmap, strand_card, y, scale, replace(plan, level_taps=chosen), zone)
    return chosen if coded_bytes(mixed) < coded_bytes(trial[4]) else (4,) * levels


def _choose_level_guide(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray,
                        plan: Prediction, zone: DeadZone) -> bool:
    """Whether each base segment's refinement residuals are stored as differences from those of the
    most alike strand before it on the card (spec 4.3, ``level_guide``) rather than the card
    neighbour's: whichever codes the strands of a sample of cards smaller. Wavy strands densified from
    fewer gain most, real strands a little, and some models lose (COMPRESSION.md, "The most alike
    strand")."""
    unguided, guided = map_threads(lambda g: coded_bytes(_sample_residuals(
        cmap, strand_card, y, scale, replace(plan, level_guide=g), zone, BASE_SAMPLE_CARDS)), [False, True])
    return guided < unguided


def _sample_residuals(cmap: CardMap, strand_card: np.ndarray, y: np.ndarray, scale: np.ndarray, plan: Prediction,
                      zone: DeadZone, cards: int = 200) -> list[np.ndarray]:
    """The residual arrays as stored (base, then each level; after neighbour prediction) of the strands
    of ``cards`` evenly spaced cards (whole cards: neighbour prediction works within them), coded with
    ``plan`` and ``zone``. 64 cards tell the neighbour zone's choice, whose margins are wide, but not
    interpolation widths whose sizes differ by a few per cent: those take 200."""
    ids = np.unique(strand_card)
    picked = ids[np.linspace(0, len(ids) - 1, min(cards, len(ids))).astype(np.int64)]
    pick = np.flatnonzero(np.isin(strand_card, picked))
    base, levels, *_ = encode_uvd(cmap, strand_card[pick], y[pick], scale[pick], plan,
                                 dead_zone=zone._replace(points=zone.points[pick]))
    return _with_neighbour_prediction(strand_card[pick], [base] + levels, plan.level_guide)[0]


def _optional_chunks(asset: HairAsset) -> list[container.Chunk]:
    out = []
    if asset.strand_ids is not None:
        w = StreamWriter()
        w.ints(np.diff(asset.strand_ids.astype(np.int64), prepend=0))
        out.append(container.Chunk("SIDS", w.getvalue(), required=False))
    if asset.root_uv is not None:
        w = StreamWriter()
        w.array(asset.root_uv.astype(np.float32), shuffle=True)
        out.append(container.Chunk("ROOT", w.getvalue(), required=False))
    if asset.source_color is not None:
        w = StreamWriter()
        w.array(np.rint(np.clip(asset.source_color, 0, 1) * 255).astype(np.uint8))
        out.append(container.Chunk("SCOL", w.getvalue(), required=False))
    if asset.metadata:
        out.append(container.Chunk("XMET", json.dumps(asset.metadata, allow_nan=False).encode("utf-8"),
                                   required=False))
    return out


def _put_hier(w: StreamWriter, y: np.ndarray, base_stride: int) -> np.ndarray:
    """Write ``y [rows, n]`` (step units) hierarchically; return it as a decoder will read it."""
    base, levels, rec = hier_encode(y, base_stride)
    w.ints(base)
    for r in levels:
        w.ints(r)
    return rec


def _get_hier(r: StreamReader, rows: int, n: int, base_stride: int, name: str) -> np.ndarray:
    base_idx, plan = level_plan(n, base_stride)
    base = r.ints((rows, len(base_idx)), f"{name} base")
    levels = [r.ints((rows, len(idx)), f"{name} level {i}") for i, (idx, _, _) in enumerate(plan)]
    return hier_decode(base, levels, n, base_stride)


def _encode_cards(cards: Cards, q: dict, w: StreamWriter) -> Cards:
    """Write the card streams; return the cards as the decoder will see them."""
    c, m1 = cards.half_width.shape
    cq, s = q["card_step"], q["base_stride"]
    spine = _put_hier(w, cards.spine.transpose(0, 2, 1).reshape(-1, m1) / cq, s)
    # the normals' angles about the spine as the decoder will have it
    _put_hier(w, normal_angles(cards.normal, spine.reshape(c, 3, m1).transpose(0, 2, 1) * cq, q["normal_bits"]), s)
    _put_hier(w, cards.half_width / cq, s)
    return _decode_cards(StreamReader(w.getvalue(), "CARD"), c, m1, q)


def _decode_cards(r: StreamReader, c: int, m1: int, q: dict) -> Cards:
    """The quantized cards' geometry; their groups (CARD's last array, :func:`_read_groups`) are left 0."""
    cq, s = q["card_step"], q["base_stride"]
    spine = _get_hier(r, c * 3, m1, s, "spine").reshape(c, 3, m1).transpose(0, 2, 1) * cq
    normal = angle_normals(_get_hier(r, c, m1, s, "normal angle"), spine, q["normal_bits"])
    half_width = np.maximum(_get_hier(r, c, m1, s, "half_width") * cq, 0.0)
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


def _uvd_scale(su: np.ndarray, sv: np.ndarray, strand_card: np.ndarray, step: float) -> np.ndarray:
    """Per strand, the factors ``[S, 3]`` that turn ``(u, v, delta)`` into quantization steps."""
    return np.stack([su[strand_card], sv[strand_card], np.ones(len(strand_card))], axis=-1) / step


def _decode_chunks(meta: dict, payloads: dict[str, bytes], sh_ahead: bool) -> tuple[HairAsset, np.ndarray | None]:
    s, p, c, m, nt, k, d = (meta[key] for key in ("strands", "points", "cards", "segments", "groups", "k",
                                                    "latent_dim"))
    q = meta["quant"]
    rd = {name: StreamReader(payloads[name], name) for name in REQUIRED_CHUNKS[1:]}
    strand_card = np.cumsum(rd["STRD"].ints((s,), "strand_card"))
    if strand_card.min() < 0 or strand_card.max() >= c:
        raise InvalidContentError(f"strand_card refers to cards outside [0, {c})", chunk="STRD")
    widths = [d] + [layer["out"] for layer in meta["mlp"]]
    sh_out = None
    if q["lossless"]:
        f4 = ("<f4",)
        cards = Cards(rd["CARD"].array((c, m + 1, 3), "spine", f4), rd["CARD"].array((c, m + 1, 3), "normal", f4),
                      rd["CARD"].array((c, m + 1), "half_width", f4), _read_groups(rd["CARD"], c))
        uvd = rd["STRD"].array((s, p, 3), "uvd", f4)
        opacity = rd["OPAC"].array((s, p - 1), "opacity", f4)
        appearance = _appearance(meta, rd["LOGT"].array((s, k), "logits", f4),
                                 rd["CBKS"].array((nt, k, d), "codebooks", f4),
                                 [MlpLayer(rd["MLPW"].array((o, i), f"mlp[{j}].weight", f4),
                                           rd["MLPW"].array((o,), f"mlp[{j}].bias", f4), layer["activation"])
                                  for j, (i, o, layer) in enumerate(zip(widths[:-1], widths[1:], meta["mlp"],
                                                                        strict=True))])
    else:
        cards = _decode_cards(rd["CARD"], c, m + 1, q)
        cards.group = _read_groups(rd["CARD"], c)
        # the strand points (whose rANS decoder runs on one core) while the appearance streams decode and,
        # sh_ahead, the SH's memory faults in; a fault in STRD is raised first, as it comes first in the file
        with ThreadPoolExecutor(max_workers=1) as background:
            points = background.submit(_decode_strand_points, rd["STRD"], cards, strand_card, p, q,
                                       payloads.get(FAMILY_CHUNK))
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
    for reader in rd.values():
        reader.finish()
    asset = HairAsset(cards, strand_card.astype(np.int32), uvd, opacity.astype(np.float32), appearance,
                      float(meta["thickness"]), float(meta["meters_per_unit"]), meta["up_axis"], meta["generator"],
                      meta["attribution"])
    _decode_optional(asset, payloads, s, p)
    return asset, sh_out


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
    _undo_neighbour_prediction(guide_card, residuals, columns, q["neighbour"])
    scale = _uvd_scale(*card_scales(cards, q["step"]), guide_card, q["step"])
    cmap = CardMap(cards)
    uvd = decode_uvd(cmap, guide_card, residuals, p, scale, _prediction(q))
    if family_payload is None:
        return uvd
    family = _read_family(family_payload, g, len(strand_card) - g)
    card = strand_card.astype(np.int64)
    guides = cmap.strands(card[:g], uvd)
    try:
        children = place_children(cmap, q["step"], guides, family.parents, family.weights, family.respaced,
                                  card[g:])
    except ValueError as exc:
        raise InvalidContentError(f"{exc} (a corrupt step or weights)", chunk=FAMILY_CHUNK) from None
    return np.concatenate([uvd, children])


def _decode_quantized_appearance(rd: dict[str, StreamReader], meta: dict, s: int, p: int, q: dict
                                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[MlpLayer]]:
    """Opacities, logits, codebooks and MLP layers of a quantized file."""
    nt, k, d = meta["groups"], meta["k"], meta["latent_dim"]
    widths = [d] + [layer["out"] for layer in meta["mlp"]]
    opacity = np.clip(_get_hier(rd["OPAC"], s, p - 1, q["base_stride"], "opacity") / q["opacity_scale"], 0, 1)
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
            asset.metadata = load_json(payloads["XMET"])
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise InvalidContentError(f"XMET is not valid UTF-8 JSON: {exc}", chunk="XMET") from None
        if not isinstance(asset.metadata, dict):
            raise InvalidContentError("XMET must be a JSON object", chunk="XMET")


def read_info(source) -> dict:
    """What ``cgh info`` prints: header, chunk table and counts, without decoding the streams."""
    data = _read_bytes(source)
    version, infos = container.verify(data, set(KNOWN_CHUNKS))
    meta_info = next((i for i in infos if i.type == "META"), None)
    if meta_info is None:
        raise InvalidContentError("required chunk 'META' is missing from the chunk table", chunk="META",
                                  offset=container.HEADER_SIZE)
    try:
        meta = _parse_meta(_meta_payload(data, meta_info))
    except CghFormatError as exc:
        raise exc.at(meta_info.offset) if exc.offset is None else exc from None
    gaussians = meta["strands"] * (meta["points"] - 1)
    return {
        "version": f"{version[0]}.{version[1]}", "file_bytes": len(data), "profile": meta["profile"],
        "strands": meta["strands"], "points_per_strand": meta["points"], "gaussians": gaussians,
        "cards": meta["cards"], "card_segments": meta["segments"], "groups": meta["groups"],
        "codebook_size": meta["k"], "latent_dim": meta["latent_dim"], "sh_degree": meta["sh_degree"],
        "weight_mode": meta["weight_mode"], "mlp": [layer["out"] for layer in meta["mlp"]],
        "thickness": meta["thickness"], "meters_per_unit": meta["meters_per_unit"], "up_axis": meta["up_axis"],
        "generator": meta["generator"], "attribution": meta["attribution"],
        "bits_per_gaussian": 8 * len(data) / gaussians, "quant": meta["quant"],
        "chunks": [{"type": i.type, "required": i.required, "codec": ["raw", "zstd"][i.codec],
                    "stored_bytes": i.stored, "raw_bytes": i.raw} for i in infos],
    }


