"""The ANIM writer's measure of an animation (cghair_format.codec.animation_error): the bounds hold, the
pruned search finds the same largest distance as mapping every point, and the writer's bytes are those
of the plain search."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cghair_format.animation import Animation
from cghair_format.codec.animation import (
    MAX_TIGHTENINGS,
    TIGHTEN_TARGET,
    animation_meta,
    encode_animation,
    encode_blocks,
    encode_within,
)
from cghair_format.codec.animation_error import PointBoxes, animation_point_error, card_bounds, reference_point_error
from cghair_format.examples import example_animation, example_asset
from cghair_format.geometry import bounding_diagonal, lengths, strand_points
from cghair_format.profiles import PROFILES


@pytest.fixture(scope="module")
def asset():
    return example_asset(5, strands=120, points=14, cards=10, segments=7)


@pytest.fixture(scope="module")
def clip(asset):
    return example_animation(asset.cards, 12)


@pytest.fixture(scope="module")
def diag(asset):
    return bounding_diagonal(strand_points(asset.cards, asset.strand_card, asset.uvd))


def _boxes(asset, uvd=None):
    uvd = asset.uvd if uvd is None else uvd
    return PointBoxes.of(uvd, asset.strand_card, asset.cards.count, asset.cards.segments)


def _decoded(asset, clip, diag, profile="compact", scale=1.0) -> Animation:
    meta = animation_meta(clip, asset.cards, PROFILES[profile], diag)
    if "step" in meta:
        meta = animation_meta(clip, asset.cards, PROFILES[profile], diag, meta["step"] * scale)
    return encode_blocks(clip, asset.cards, meta)[1]


def _card_distances(asset, source, decoded, frame, uvd) -> np.ndarray:
    """Per card, the largest distance of its points on the two versions of ``frame``, every point mapped."""
    a = strand_points(source.cards(asset.cards, frame), asset.strand_card, uvd).astype(np.float64)
    b = strand_points(decoded.cards(asset.cards, frame), asset.strand_card, uvd)
    per_strand = lengths(a - b).max(axis=1)
    out = np.zeros(asset.cards.count)
    np.maximum.at(out, asset.strand_card, per_strand)
    return out


@pytest.mark.parametrize("scale", [0.3, 1.0, 8.0])
def test_the_bounds_hold_for_every_card(asset, clip, diag, scale):
    decoded = _decoded(asset, clip, diag, scale=scale)
    boxes = _boxes(asset)
    for f in range(clip.frames):
        bound = card_bounds(clip.cards(asset.cards, f), decoded.cards(asset.cards, f), boxes)
        exact = _card_distances(asset, clip, decoded, f, asset.uvd)
        assert (exact <= bound).all()
        assert (bound <= 3 * exact.max() + 1e-9 * diag).all()  # a bound that is of use: near the truth


def test_the_bounds_hold_off_the_strip(asset, clip, diag):
    """Points past the card's ends and sides, and far off it, extrapolate the triangles' frames."""
    rng = np.random.default_rng(1)
    uvd = asset.uvd.copy()
    uvd[..., 0] += rng.uniform(-0.3, 0.3, uvd.shape[:2]).astype(np.float32)
    uvd[..., 1] = rng.uniform(-1.5, 2.5, uvd.shape[:2]).astype(np.float32)
    uvd[..., 2] *= 20
    decoded = _decoded(asset, clip, diag, scale=4.0)
    boxes = _boxes(asset, uvd)
    for f in range(0, clip.frames, 3):
        bound = card_bounds(clip.cards(asset.cards, f), decoded.cards(asset.cards, f), boxes)
        assert (_card_distances(asset, clip, decoded, f, uvd) <= bound).all()


@pytest.mark.parametrize("profile,scale", [("compact", 1.0), ("compact", 5.0), ("high", 1.0), ("lossless", 1.0)])
def test_the_search_finds_what_mapping_every_point_finds(asset, clip, diag, profile, scale):
    decoded = _decoded(asset, clip, diag, profile, scale)
    fast = animation_point_error(_boxes(asset), clip, decoded, asset.cards, asset.uvd)
    assert fast == reference_point_error(asset.uvd, asset.strand_card, clip, decoded, asset.cards)
    assert (fast == 0) == (profile == "lossless")


def test_one_moved_card_is_found(asset, clip, diag):
    """A single card of a single frame far off: the worst bound leads the search to it."""
    decoded = _decoded(asset, clip, diag)
    spine = decoded.spine.copy()
    spine[7, 3, 4] += np.float32(0.01 * diag)
    moved = Animation(spine, decoded.normal, clip.fps)
    fast = animation_point_error(_boxes(asset), clip, moved, asset.cards, asset.uvd)
    assert fast == reference_point_error(asset.uvd, asset.strand_card, clip, moved, asset.cards) > 0.004 * diag


def _plain_search(animation, rest, prof, diag, uvd, strand_card):
    """The writer's step search as it was: every step compressed, every point of every frame mapped."""
    tol = prof.position_tolerance * diag
    meta = animation_meta(animation, rest, prof, diag)
    for _ in range(MAX_TIGHTENINGS):
        payload, decoded = encode_animation(animation, rest, meta, prof.zstd_level)
        error = reference_point_error(uvd, strand_card, animation, decoded, rest)
        if prof.lossless or error <= tol:
            break
        meta = animation_meta(animation, rest, prof, diag, meta["step"] * TIGHTEN_TARGET * tol / error)
    return meta, payload, error


@pytest.mark.parametrize("profile", ["compact", "high", "lossless"])
def test_the_writer_stores_the_plain_search_s_bytes(asset, diag, profile):
    """Cards 16 times as wide turn their rails by more with the spines' error: the search tightens."""
    wide = replace(asset, cards=replace(asset.cards, half_width=asset.cards.half_width * 16))
    clip = example_animation(wide.cards, 12)
    prof = PROFILES[profile]
    meta, payload, report = encode_within(clip, wide.cards, prof, diag, wide.uvd, wide.strand_card)
    assert (meta, payload, report.max_point_error) == _plain_search(clip, wide.cards, prof, diag, wide.uvd,
                                                                    wide.strand_card)
    assert prof.lossless or meta["step"] < animation_meta(clip, wide.cards, prof, diag)["step"]
