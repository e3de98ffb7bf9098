"""The chunk writer: an asset's settled, quantized streams -> the chunks' payloads (spec: "Chunks").

Nothing here chooses anything: the step, the strand coder's plan and the residuals come from the
writer (:mod:`.writer`, :mod:`.choices`); this module lays them out as the reader (:mod:`.reader`)
expects them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .. import container, rans
from ..asset import Cards, HairAsset
from ..geometry import normal_angles
from ..profiles import Profile
from ..quantize import hier_encode, softmax_levels_encode, weights_encode
from ..residual_coder import NEIGHBOUR_CLASSES, write_residuals
from ..strand_coder import neighbour_encode, neighbour_order
from ..streams import StreamReader, StreamWriter
from .layout import COUNTS_CHUNK, FAMILY_CHUNK, Family
from .reader import decode_cards


def geometry_chunks(asset: HairAsset, meta: dict, cards_w: StreamWriter, residuals: list[np.ndarray] | None,
                    family: Family | None) -> list[container.Chunk]:
    """CARD and STRD (and CHLD with a ``family``, PCNT where some strand has fewer points) once the step
    is settled: the ``residuals`` (None: lossless, the card coordinates as float32) go through
    neighbour prediction and the entropy coder, which fill META's ``quant.neighbour`` and
    ``quant.neighbour_classes`` (the writer stores META last: the opacities add to it)."""
    strd_w = StreamWriter()
    strd_w.ints(np.diff(asset.strand_card.astype(np.int64), prepend=0))
    if residuals is None:
        strd_w.array(asset.uvd.astype(np.float32), shuffle=True)
    else:
        coded = asset.strand_card[:len(residuals[0])]  # the guides, where there are children (spec 4.5)
        stored, meta["quant"]["neighbour"] = with_neighbour_prediction(coded, residuals,
                                                                       bool(meta["quant"]["level_guide"]))
        meta["quant"]["neighbour_classes"] = write_residuals(strd_w, stored, coded, (NEIGHBOUR_CLASSES, 1))
    groups = asset.cards.group.astype(np.uint16 if asset.appearance.n_groups <= 65536 else np.uint32)
    cards_w.array(groups, shuffle=True)
    chunks = [container.Chunk("CARD", cards_w.getvalue()), container.Chunk("STRD", strd_w.getvalue())]
    if family is not None and len(family.parents):
        chunks.append(container.Chunk(FAMILY_CHUNK, family_payload(family)))
    if asset.variable:
        counts_w = StreamWriter()
        counts_w.ints(asset.point_counts)
        chunks.append(container.Chunk(COUNTS_CHUNK, counts_w.getvalue()))
    return chunks


def family_payload(family: Family) -> bytes:
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


@dataclass(frozen=True)
class OpacityMarks:
    """What the writer did with the opacities marked negligible (:func:`.writer.encode`'s ``negligible``):
    a quantized profile codes OPAC twice, plain and with the marked opacities anywhere from 0 up to their
    own (spec 4.4, "Lowered opacities"), and keeps the smaller."""

    marked: int  # the Gaussians marked (placeholders' segments aside)
    lowered: int  # of those, how many the marked stream stores more than half a step below their own opacity
    kept: bool  # whether OPAC is the marked stream (then META records ``lowered``, spec 2.1)
    plain_bytes: int  # OPAC's stored bytes without the marks ...
    marked_bytes: int | None  # ... and with them (None: no marked stream, lossless or nothing marked)
    budget: float | None = None  # the share of the blend weight the marks carry, as the caller said

    def summary(self) -> str:
        """The figures in a line, as ``cgh encode`` prints them."""
        budget = "" if self.budget is None else f" (budget {self.budget:g})"
        if self.marked_bytes is None:
            return (f"opacities: {self.marked:,} marked negligible{budget}; stored plain, every one within the "
                    "profile's bound (lossless: exact)")
        verdict = (f"kept the marked stream: {self.lowered:,} stored lower, down to 0" if self.kept else
                   "kept the plain stream: every opacity within the bound")
        return (f"opacities: {self.marked:,} marked negligible{budget}; OPAC {self.marked_bytes:,} bytes with the "
                f"marks, {self.plain_bytes:,} without; {verdict}")


def appearance_chunks(asset: HairAsset, prof: Profile, quant: dict, negligible: np.ndarray | None = None
                      ) -> tuple[list[container.Stored], OpacityMarks | None]:
    """OPAC, LOGT, CBKS and MLPW, then the optional chunks, compressed at the profile's zstd level: none
    depends on the point step (the opacities take the file's base stride, ``quant``); and what became
    of the ``negligible`` marks (None: none given), :func:`opacity_chunk`."""
    logt_w, cbks_w, mlp_w = (StreamWriter() for _ in range(3))
    app = asset.appearance
    if prof.lossless:
        logt_w.array(app.logits.astype(np.float32), shuffle=True)
        cbks_w.array(app.codebooks.astype(np.float32), shuffle=True)
        for layer in app.mlp:
            mlp_w.array(layer.weight.astype(np.float32), shuffle=True)
            mlp_w.array(layer.bias.astype(np.float32), shuffle=True)
    else:
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
    opac, marks = opacity_chunk(asset, prof, quant, negligible)
    rest = [container.Chunk(t, w.getvalue()) for t, w in (("LOGT", logt_w), ("CBKS", cbks_w), ("MLPW", mlp_w))]
    return [opac] + [container.compress(c, prof.zstd_level) for c in rest + _optional_chunks(asset)], marks


def opacity_chunk(asset: HairAsset, prof: Profile, quant: dict, negligible: np.ndarray | None
                  ) -> tuple[container.Stored, OpacityMarks | None]:
    """OPAC, compressed, and what became of the ``negligible`` marks (None: none given). Quantized, OPAC
    is also coded with the marked opacities anywhere from 0 up to their own (see
    :func:`.writer.encode`), and the smaller of the two is kept: a barely trained file's smooth
    opacities can code better as they are than with some samples taken down."""
    w = StreamWriter()
    marked = 0 if negligible is None else int(np.count_nonzero(negligible & asset.real_segments()))
    if prof.lossless:
        w.array(asset.opacity.astype(np.float32), shuffle=True)
    else:
        opacity = asset.opacity * prof.opacity_scale
        put_hier(w, opacity, quant["base_stride"])
    plain = container.compress(container.Chunk("OPAC", w.getvalue()), prof.zstd_level)
    if negligible is None or prof.lossless or not marked:
        return plain, None if negligible is None else OpacityMarks(marked, 0, False, len(plain.body), None)
    w = StreamWriter()
    rec = put_hier(w, opacity, quant["base_stride"], negligible)
    # a decoder clamps at 0 (spec 4.4): below the bound is more than half a step under the opacity
    lowered = int(np.count_nonzero((np.maximum(rec, 0) < opacity - 0.5) & negligible & asset.real_segments()))
    with_marks = container.compress(container.Chunk("OPAC", w.getvalue()), prof.zstd_level)
    kept = len(with_marks.body) <= len(plain.body)  # (the marked stream where the two tie)
    return (with_marks if kept else plain), OpacityMarks(marked, lowered, kept, len(plain.body), len(with_marks.body))


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


def lossless_cards(cards: Cards) -> StreamWriter:
    """CARD's geometry streams of a lossless file: every float32 as it is."""
    w = StreamWriter()
    for a in (cards.spine, cards.normal, cards.half_width):
        w.array(a.astype(np.float32), shuffle=True)
    return w


def quantized_cards(cards: Cards, q: dict) -> tuple[StreamWriter, Cards]:
    """CARD's geometry streams at ``q["card_step"]``, and the cards as the decoder will see them."""
    w = StreamWriter()
    c, m1 = cards.half_width.shape
    cq, s = q["card_step"], q["base_stride"]
    spine = put_hier(w, cards.spine.transpose(0, 2, 1).reshape(-1, m1) / cq, s)
    # the normals' angles about the spine as the decoder will have it
    put_hier(w, normal_angles(cards.normal, spine.reshape(c, 3, m1).transpose(0, 2, 1) * cq, q["normal_bits"]), s)
    put_hier(w, cards.half_width / cq, s)
    return w, decode_cards(StreamReader(w.getvalue(), "CARD"), c, m1, q)


def put_hier(w: StreamWriter, y: np.ndarray, base_stride: int, lowerable: np.ndarray | None = None) -> np.ndarray:
    """Write ``y [rows, n]`` (step units) hierarchically (spec 4.1), each sample within half a step, or
    where ``lowerable`` anywhere from -0.5 up (:func:`.quantize.hier_encode`); return it as a decoder
    will read it."""
    base, levels, rec = hier_encode(y, base_stride, lowerable)
    w.ints(base)
    for r in levels:
        w.ints(r)
    return rec


def with_neighbour_prediction(strand_card: np.ndarray, residuals: list[np.ndarray], level_guide: bool = False
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
            if rans.estimate_bytes(diff) < rans.estimate_bytes(r[..., ch]):
                r[..., ch] = diff
                mask |= 1 << ch
        stored.append(r)
        masks.append(mask)
    return stored, masks


def _narrowest(top: int) -> type:
    """The narrowest unsigned integer type that holds ``0 .. top``."""
    return next(t for t in (np.uint8, np.uint16, np.uint32) if top <= np.iinfo(t).max)
