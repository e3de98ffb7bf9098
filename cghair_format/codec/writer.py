"""HairAsset -> .cgh bytes: the step search that meets the profile's bound, measured on the points a
decoder will get, and the strands' arrangement in the file (spec 4.3, 4.5).

The per-file choices of the strand coder are :mod:`.choices`'; the chunks' layout is :mod:`.chunks`'.
"""

from __future__ import annotations

import json
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from .. import container, memory
from ..animation.clip import Animation
from ..asset import Cards, HairAsset
from ..atomic import write_bytes
from ..children import WEIGHT_ONE, Children, best_weights, find_children, fit_weights, place_children
from ..errors import AssetError
from ..geometry import CardMap, bounding_diagonal, card_scales, lengths, strand_points
from ..parallel import map_blocks, map_threads
from ..profiles import DEFAULT_PROFILE, PROFILES, Profile, get_profile
from ..quantize import weight_steps
from ..strand_coder import NEWTON_HALVINGS, STRETCH_MAX, Coded, DeadZone, canonical_order, coded_uvd, encode_uvd
from ..streams import StreamReader, StreamWriter
from . import choices as choosing
from . import schema
from .animation import AnimationReport, encode_within
from .choices import Choices
from .chunks import OpacityMarks, appearance_chunks, geometry_chunks, lossless_cards, quantized_cards
from .layout import ANIM_CHUNK, Family, prediction, uvd_scale
from .reader import read_cards

MIN_CHILD_SHARE = 0.1  # interpolated strands are stored where at least this share of the strands are (below
# it the guides' chains lose more than the few children save; docs/compression.md, "Interpolated strands")
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
# the step with the error would cost the whole file for one point (docs/compression.md, "The writer's per-file choices")
NUDGES = 4  # ... up to this many times: a point far off a twisting card (|delta| 15 units off a 78-unit card) moves
# 3.4 steps for a step of u, so its miss is where the lattice falls, not the step's size, and a step shrunk with
# the error can miss by more (docs/compression.md, "Far points and the step")
DEAD_ZONE = 0.97  # a refinement residual stays zero where the prediction is this close to the input (x tol)


@dataclass(frozen=True)
class EncodeOptions:
    """How :func:`encode` writes an asset: built by :meth:`of` from what the API and CLI take."""

    profile: Profile
    keep_order: bool = False  # the input's strand order, and no children, at a cost (lossless: always)

    @classmethod
    def of(cls, profile: str | Profile = DEFAULT_PROFILE, keep_order: bool = False) -> EncodeOptions:
        """The options for a profile name (or :class:`Profile`); ``ValueError`` for an unknown name."""
        return cls(get_profile(profile), bool(keep_order))

    @property
    def reorder(self) -> bool:
        """Whether the strands are stored card by card and as children (spec 4.3, 4.5)."""
        return not self.profile.lossless and not self.keep_order


@dataclass
class EncodeReport:
    profile: str
    step: float | None  # strand-point quantization step (scene units), None if lossless
    max_point_error: float  # largest Euclidean distance to the input point, measured, scene units
    bbox_diagonal: float
    chunk_sizes: dict[str, int] = field(default_factory=dict)  # stored bytes per chunk
    # the file's strand i is the input's strand_order[i] (None: the input's order, kept)
    strand_order: np.ndarray | None = None
    opacity: OpacityMarks | None = None  # what became of the negligible marks (None: none given)
    animation: AnimationReport | None = None  # what the animation's quantization measured (None: none given)

    def in_file_order(self, asset: HairAsset) -> HairAsset:
        """The encoded ``asset`` with its strands in the order the file stores them."""
        return asset if self.strand_order is None else asset.take_strands(self.strand_order)

    def strands_in_file_order(self, per_strand: np.ndarray) -> np.ndarray:
        """A per-strand array of the input (``[S, ...]``, such as its points) in the file's strand order."""
        return per_strand if self.strand_order is None else per_strand[self.strand_order]


def write(asset: HairAsset, path: str | os.PathLike, profile: str | Profile = DEFAULT_PROFILE,
          keep_order: bool = False, negligible: np.ndarray | None = None,
          opacity_budget: float | None = None, animation: Animation | None = None) -> EncodeReport:
    """Write ``asset`` to ``path`` atomically (:mod:`.atomic`); see :func:`encode`."""
    data, report = encode(asset, profile, keep_order, negligible, opacity_budget, animation)
    write_bytes(path, data)
    return report


def encode(asset: HairAsset, profile: str | Profile = DEFAULT_PROFILE, keep_order: bool = False,
           negligible: np.ndarray | None = None, opacity_budget: float | None = None,
           animation: Animation | None = None) -> tuple[bytes, EncodeReport]:
    """Serialise a validated asset; returns the bytes and what the quantization measured.

    The quantized profiles store the strands card by card, alike strands one after another (spec 4.3),
    and strands that blend others last, as children of those (4.5), which codes smaller:
    ``report.strand_order`` maps them back to the input's (the asset's optional per-strand data travel
    with their strands). ``keep_order`` keeps the input's order instead, and stores no children, at a
    cost; the lossless profile always keeps it. The encoder's arrays, short-lived, do without huge pages
    (:func:`.memory.without_huge_pages`).

    ``negligible`` (bool ``[S, P-1]``, like ``asset.opacity``) marks segments whose Gaussians hardly
    show (``training.visibility``): a quantized profile may store their opacities anywhere from 0 up
    to their own, where that codes smaller; every other opacity keeps the profile's bound. The lossless
    profile stores every opacity as it is. Where the file stores some lower, META says how many and
    ``opacity_budget`` (the share of the blend weight the marked Gaussians carry, in [0, 1], if known)
    (spec 4.4, "Lowered opacities"); ``report.opacity`` has the figures.

    ``animation`` (frames of the asset's cards, :class:`~..animation.Animation`) is stored in ANIM (spec
    4.6) at the profile's precision; ``report.animation`` has its size and measured error."""
    options = EncodeOptions.of(profile, keep_order)
    if animation is not None:
        animation.validate(asset.cards)
    if negligible is not None:
        negligible = np.asarray(negligible)
        if negligible.dtype != bool or negligible.shape != np.shape(asset.opacity):
            raise ValueError(f"negligible must be a bool array shaped like the opacities "
                             f"{np.shape(asset.opacity)}, got {negligible.dtype} {negligible.shape}")
    if opacity_budget is not None and (negligible is None or not 0 <= opacity_budget <= 1):
        raise ValueError(f"opacity_budget is the share of the blend weight that the negligible marks carry, in "
                         f"[0, 1], and needs them: got {opacity_budget} with "
                         f"{'no marks' if negligible is None else 'marks'}")
    with memory.without_huge_pages():
        return _encode(asset, options, negligible, opacity_budget, animation)


class _Geometry(NamedTuple):
    """What depends on the point step: META, the CARD streams, and (quantized profiles) the STRD
    residual arrays, the world points a decoder will get and the choices made."""

    meta: dict
    cards: StreamWriter
    residuals: list[np.ndarray] | None
    decoded_points: np.ndarray | None
    choices: Choices | None
    family: Family | None = None  # the interpolated strands, with their weights fitted to the decoded guides
    coding: _Coding | None = None  # with a family: what coding more guides after these takes


class _Coding(NamedTuple):
    """The strand coder's state with a family (:func:`_with_late_guides`): the quantized cards' map, the
    guides' input card coordinates on them (file order), the coder's state and the dead zone's reach."""

    cmap: CardMap
    cards: Cards
    card_uvd: np.ndarray
    state: Coded
    zone_distance: float


class _Passed(NamedTuple):
    """The largest step tried that met the bound: its measured error, geometry, and file order."""

    step: float | None
    error: float
    geometry: _Geometry
    asset: HairAsset
    order: np.ndarray | None


def _encode(asset: HairAsset, options: EncodeOptions, negligible: np.ndarray | None, budget: float | None,
            animation: Animation | None) -> tuple[bytes, EncodeReport]:
    asset = asset.validate().with_placeholders()
    prof = options.profile.for_opacities(asset.opacity[asset.real_segments()])
    points = strand_points(asset.cards, asset.strand_card, asset.uvd)
    diag = bounding_diagonal(points)
    schema.check_writable(_meta(asset, PROFILES["lossless"], None, diag))  # counts and scalars, before the search
    points = points.astype(np.float64)
    passed = _search_step(asset, points, prof, diag, options.reorder)
    asset, geometry = passed.asset, passed.geometry
    if negligible is not None and passed.order is not None:
        negligible = negligible[passed.order]
    level, quant = prof.zstd_level, dict(geometry.meta["quant"])
    with ThreadPoolExecutor(max_workers=1) as background:  # zstd on the appearance while STRD is coded
        appearance = background.submit(appearance_chunks, asset, prof, quant, negligible)
        chunks = geometry_chunks(asset, geometry.meta, geometry.cards, geometry.residuals, geometry.family)
        stored = map_threads(lambda c: container.compress(c, level), chunks)
        appearance, marks = appearance.result()
    marks = None if marks is None else replace(marks, budget=budget)
    if marks is not None and marks.kept:  # the record of spec 4.4's "Lowered opacities", in META
        geometry.meta["quant"].update(opacity_lowered=marks.lowered, **(
            {} if budget is None else {"opacity_budget": float(budget)}))
    moving = [] if animation is None else [_animation_chunk(asset, prof, geometry.meta, stored[0], animation)]
    meta = container.compress(container.Chunk("META", schema.dump(geometry.meta)), level)
    data = container.assemble([meta] + stored + appearance + [m[0] for m in moving])
    _, infos = container.read_table(data)
    return data, EncodeReport(prof.name, passed.step, passed.error, diag, {i.type: i.stored for i in infos},
                              passed.order, marks, moving[0][1] if moving else None)


def _animation_chunk(asset: HairAsset, prof: Profile, meta: dict, card: container.Stored, animation: Animation
                     ) -> tuple[container.Stored, AnimationReport]:
    """ANIM (stored raw: its blocks are compressed on their own) for ``animation`` of the rest cards as a
    decoder gets them from ``card`` (CARD), with META's ``animation`` object added to ``meta``; and what
    it measured, the points' error on the file's strands (within the profile's tolerance of them on the
    input frames: :func:`.animation.encode_within`)."""
    rest = read_cards(StreamReader(card.chunk.payload, "CARD"), meta)
    meta["animation"], payload, report = encode_within(animation, rest, prof, meta["bbox_diagonal"], asset.uvd,
                                                       asset.strand_card)
    return container.Stored(container.Chunk(ANIM_CHUNK, payload, required=False), container.CODEC_RAW, payload), report


def _search_step(input_asset: HairAsset, input_points: np.ndarray, prof: Profile, diag: float, reorder: bool
                 ) -> _Passed:
    """The largest point step the search finds whose decoded points lie within the profile's bound of
    ``input_points`` (``[S, P, 3]``, float64), with the file order (``reorder``: card by card, and the
    interpolated strands as children where there are enough of them)."""
    tol = prof.position_tolerance * max(diag, 1e-12)
    # (a variable-count file stores no children: a blend of padded strands seldom fits a strand's own points)
    kids = find_children(input_points, tol) if reorder and not input_asset.variable else None
    if kids is not None and np.count_nonzero(kids.child) < MIN_CHILD_SHARE * len(input_points):
        kids = None  # a few children cost their guides more than they save
    arranged = _arrange(input_asset, input_points, kids) if reorder else (input_asset, input_points, None, None)
    # the largest point error is typically about 1.0 step (half a step on each of u, v, delta): start
    # where it usually meets the bound at once, then tighten or grow
    step = None if prof.lossless else STEP_START * tol
    passed = None
    chosen, nudges = None, 0
    for attempt in range(MAX_TIGHTENINGS + NUDGES):
        asset, points, order, family = arranged
        geometry = _quantize_geometry(asset, prof, step, diag, points, tol, chosen, family)
        chosen = geometry.choices
        dist = _distances(geometry, points, asset)
        if family is not None and (dist[family.guides:] > tol).any():
            # children that the decoded guides place too far become guides, last on their cards (the
            # guides before them decode as they did, so the other children stay where they were)
            late = np.zeros(len(input_points), bool)
            late[order[family.guides:][(dist[family.guides:] > tol).any(axis=1)]] = True
            before = order
            asset, points, order, family = _arrange(input_asset, input_points, kids, late, order[:family.guides])
            geometry = _with_late_guides(geometry, before, order, family.guides, asset, points)
            dist = _distances(geometry, points, asset)
        err = float(dist.max())
        if step is None:
            return _Passed(step, err, geometry, asset, order)
        if err <= tol:
            passed = _Passed(step, err, geometry, asset, order)
            if attempt > 0 or err >= GROW_BELOW * tol:
                break  # only a first step well inside the bound is retried larger
        elif passed is not None:
            break
        if err > tol and nudges < NUDGES and np.count_nonzero(dist > tol) <= max(1, dist.size // NUDGE_RARE):
            step, nudges = step * NUDGE, nudges + 1
        else:
            step *= TIGHTEN_TARGET * tol / err if err > 0 else 1 / GROW_BELOW
    if passed is None:
        raise AssetError(f"could not meet the position tolerance {tol:g} (error {err:g})")
    return passed


def _distances(geometry: _Geometry, points: np.ndarray, asset: HairAsset) -> np.ndarray:
    """How far each point a decoder gets lies from the input's ``points`` (``[S, P]``; lossless: 0), by
    blocks of strands on every core (the differences of a block stay in cache); 0 at the placeholders of
    a variable-count ``asset`` (a decoder drops them)."""
    decoded = geometry.decoded_points
    if decoded is None:
        return np.zeros((1, 1))
    out = np.empty(points.shape[:2])
    map_blocks(lambda b: np.copyto(out[b], lengths(decoded[b] - points[b])), len(points))
    if asset.variable:
        out[~asset.real_points()] = 0.0
    return out


def _meta(asset: HairAsset, prof: Profile, step: float | None, diag: float) -> dict:
    """META (:mod:`.schema`) but for the strand coder's choices (:func:`_quantize_geometry` adds them) and
    the neighbour prediction's masks and token classes (:func:`.chunks.geometry_chunks`)."""
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
            "normal_bits": choosing.normal_bits(asset, prof), "base_stride": prof.base_strides[0],
            "newton_halvings": NEWTON_HALVINGS, "stretch_max": STRETCH_MAX,
            "opacity_scale": prof.opacity_scale, "logit_levels": prof.logit_levels, "logit_floor": prof.logit_floor,
            "weight_steps": weight_steps(app.codebooks, [(x.weight, x.bias) for x in app.mlp], prof.weight_step,
                                         prof.mlp_fraction),
            **({"position_tolerance": prof.position_tolerance} if prof.states_tolerance else {})},
    }


def _arrange(asset: HairAsset, points: np.ndarray, kids: Children | None, late: np.ndarray | None = None,
             chains: np.ndarray | None = None) -> tuple[HairAsset, np.ndarray, np.ndarray, Family | None]:
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
    family = Family(len(guides), parents[by_parent], kids.weights[children[by_parent]],
                    kids.respaced[children[by_parent]])
    return asset.take_strands(order), points[order], order, family


def _quantize_geometry(asset: HairAsset, prof: Profile, step: float | None, diag: float, points: np.ndarray,
                       tol: float, chosen: Choices | None = None, family: Family | None = None) -> _Geometry:
    """What depends on the step: META, the CARD streams, and (quantized profiles) the STRD residual
    arrays and the world points a decoder will get (``points``: the input's), with the strand coder's
    choices ``chosen`` (None: made here). With a ``family`` STRD codes the guides, and the children
    are placed on the decoded ones (:func:`_place_family`)."""
    meta = _meta(asset, prof, step, diag)
    q = meta["quant"]
    if q["lossless"]:
        return _Geometry(meta, lossless_cards(asset.cards), None, None, None)
    coded = asset if family is None else asset.take_strands(np.arange(family.guides))
    zone = DeadZone(points[:coded.n_strands], DEAD_ZONE * prof.position_tolerance * diag,
                    counts=coded.counts if coded.variable else None)  # placeholders: any residual (spec 3)
    stride, guide = ((chosen.base_stride, chosen.base_guide) if chosen is not None
                     else choosing.choose_base_samples(coded, q, zone, prof.base_strides))
    q["base_stride"] = stride  # before the cards, whose coding takes it too
    strand_card = asset.strand_card
    asset = coded  # the children's card coordinates come from their parents (4.5)
    cards_w, cards, cmap, uvd = _quantized_cards(asset, q, points[:asset.n_strands], tol)
    scale = uvd_scale(*card_scales(cards, q["step"]), asset.strand_card, q["step"])
    y = uvd * scale[:, None, :]
    if chosen is None:
        chosen = choosing.choose(cmap, asset.strand_card, y, scale, q, zone, guide)
    q["base_order"], q["base_guide"], q["newton_steps"] = list(chosen.base_order), chosen.base_guide, \
        chosen.newton_steps
    q["level_taps"], q["level_guide"] = list(chosen.level_taps), int(chosen.level_guide)
    base, levels, decoded_points, state = encode_uvd(
        cmap, asset.strand_card, y, scale, prediction(q), dead_zone=zone._replace(neighbour=chosen.neighbour_zone),
        room=0 if family is None else len(points))
    if family is None:
        return _Geometry(meta, cards_w, [base] + levels, decoded_points, chosen)
    q["children"] = len(family.parents)
    family, world = _place_family(cmap, q["step"], strand_card, coded_uvd(state, scale), family, points)
    return _Geometry(meta, cards_w, [base] + levels, world, chosen, family,
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
    from ..cards.inverse import points_on_cards  # (the card builder's package: loaded when a file is written)

    card = asset.strand_card[:guides]
    on_cards, _ = points_on_cards(coding.cards, coding.cmap, card[g0:], asset.uvd[g0:guides], points[g0:guides],
                                  1e-3 * q["step"])
    uvd = np.concatenate([coding.card_uvd, on_cards])
    scale = uvd_scale(*card_scales(coding.cards, q["step"]), card, q["step"])
    zone = DeadZone(points[:guides], coding.zone_distance, geometry.choices.neighbour_zone)
    base, levels, _, state = encode_uvd(coding.cmap, card, uvd * scale[:, None, :], scale, prediction(q),
                                        dead_zone=zone, before=coding.state)
    late_world = coding.cmap.strands(card[g0:], coded_uvd(state, scale, g0))
    world = np.concatenate([geometry.decoded_points[:g0], late_world.astype(np.float32).astype(np.float64),
                            geometry.decoded_points[kids]])
    kept = Family(guides, family.parents[kids - g0], family.weights[kids - g0], family.respaced[kids - g0])
    return _Geometry(meta, geometry.cards, [base] + levels, world, geometry.choices, kept,
                     coding._replace(card_uvd=uvd, state=state))


def _place_family(cmap: CardMap, step: float, strand_card: np.ndarray, guides_uvd: np.ndarray, family: Family,
                  points: np.ndarray) -> tuple[Family, np.ndarray]:
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
    from ..cards.inverse import points_on_cards  # (the card builder's package: loaded when a file is written)

    while True:
        cards_w, cards = quantized_cards(asset.cards, q)
        cmap = CardMap(cards)
        uvd, miss = points_on_cards(cards, cmap, asset.strand_card, asset.uvd, points, 1e-3 * q["step"])
        if miss <= CARD_MISS_SHARE * tol or q["card_step"] <= MIN_CARD_STEP_FRACTION * q["step"]:
            return cards_w, cards, cmap, uvd
        q["card_step"] /= 2

