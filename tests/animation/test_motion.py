"""Head motions, cards driven by the solver, frame decoding and SH that turns with its segment."""

from __future__ import annotations

import numpy as np
import pytest

from cghair_format import decode_gaussians
from cghair_format.animation import (
    MOTIONS,
    Animation,
    Head,
    Scene,
    SolverSettings,
    builtin_track,
    card_frames,
    fit_head,
    frame_asset,
    frame_points,
    simulate,
)
from cghair_format.animation.shading import frame_gaussians, rotate_sh, segment_rotations
from cghair_format.animation.tracks import axis_rotation
from cghair_format.errors import AssetError, CghError
from cghair_format.examples import example_asset
from cghair_format.gaussians import decode_strands, sh_polynomial
from cghair_format.geometry import spine_tangents, strand_points


def test_fit_head_finds_the_sphere_of_the_roots_and_clears_the_other_points():
    d = np.random.default_rng(0).normal(size=(200, 3))
    roots = np.array([0.1, 1.6, 0.0]) + 0.09 * d / np.linalg.norm(d, axis=1, keepdims=True)
    head = fit_head(roots, roots * 1.0 + [0, 0.2, 0], "Y")
    assert np.allclose(head.centre, [0.1, 1.6, 0.0], atol=1e-9) and head.radius <= 0.09
    inside = np.linalg.norm(roots + [0, 0.2, 0] - head.centre, axis=1) < head.radius
    assert not inside.any() and np.array_equal(head.up, [0, 1, 0])
    with pytest.raises(CghError):
        fit_head(roots[:3], roots, "Y")


@pytest.mark.parametrize("motion", MOTIONS)
def test_every_motion_starts_at_rest_and_stays_rigid(motion):
    head = Head(np.array([0.0, 1.6, 0.0]), 0.09, np.array([0.0, 1.0, 0.0]))
    track = builtin_track(motion, head, 45, 30.0, 1.0)
    assert np.allclose(track.rotation[0], np.eye(3)) and np.allclose(track.translation[0], 0)
    assert np.allclose(track.rotation @ track.rotation.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    with pytest.raises(CghError):
        builtin_track("dance", head, 10, 30.0, 1.0)


def _scene(asset, motion: str, frames: int = 12, fps: float = 30.0) -> Scene:
    points = strand_points(asset.cards, asset.strand_card, asset.uvd)
    others = np.concatenate([points[:, 1:].reshape(-1, 3), asset.cards.spine[:, 1:].reshape(-1, 3)])
    head = fit_head(points[:, 0], others, asset.up_axis)
    return Scene(builtin_track(motion, head, frames, fps, asset.meters_per_unit), head.capsules(),
                 asset.meters_per_unit, head.up)


def test_still_cards_without_gravity_keep_the_rest_pose():
    asset = example_asset()
    frames = list(card_frames(asset.cards, _scene(asset, "still"), SolverSettings(gravity=False)))
    assert len(frames) == 12
    for cards in frames:
        assert np.abs(cards.spine - asset.cards.spine).max() < 1e-6
        assert np.abs(cards.normal - asset.cards.normal).max() < 1e-5


def test_driven_cards_keep_their_lengths_and_unit_normals_across_their_spines():
    asset = example_asset()
    rest = np.linalg.norm(np.diff(asset.cards.spine.astype(np.float64), axis=1), axis=-1)
    for cards in card_frames(asset.cards, _scene(asset, "shake"), SolverSettings()):
        lengths = np.linalg.norm(np.diff(cards.spine.astype(np.float64), axis=1), axis=-1)
        assert np.abs(lengths - rest).max() < 1e-5 * rest.max()
        n, t = cards.normal.astype(np.float64), spine_tangents(cards.spine.astype(np.float64))
        assert np.abs(np.linalg.norm(n, axis=-1) - 1).max() < 1e-5 and np.abs((n * t).sum(-1)).max() < 1e-5


def test_a_simulation_is_the_same_every_run_and_its_wind_follows_the_seed():
    asset = example_asset()
    settings = SolverSettings(wind=(2.0, 0.0, 0.0), wind_gust=0.5)
    runs = [np.stack(list(simulate(asset.cards.spine, _scene(asset, "nod"), settings))) for _ in range(2)]
    assert np.array_equal(*runs)
    scene = _scene(asset, "nod")
    other = np.stack(list(simulate(asset.cards.spine, Scene(scene.track, scene.capsules, scene.meters_per_unit,
                                                             scene.up, seed=7), settings)))
    assert not np.array_equal(runs[0], other)


def _turned(asset, angles) -> Animation:
    turns = [axis_rotation(np.array([0.0, 1.0, 0.0]), a) for a in angles]
    return Animation(np.stack([asset.cards.spine @ r.T for r in turns]).astype(np.float32),
                     np.stack([asset.cards.normal @ r.T for r in turns]).astype(np.float32), 24.0)


def test_a_frame_decodes_as_the_asset_with_its_cards_moved():
    asset = example_asset()
    anim = _turned(asset, [0.0, 0.4])
    anim.validate(asset.cards)
    moved = frame_asset(asset, anim, 1)
    assert np.array_equal(frame_points(asset, anim, 1), strand_points(moved.cards, asset.strand_card, asset.uvd))
    turn = axis_rotation(np.array([0.0, 1.0, 0.0]), 0.4)
    assert np.abs(decode_strands(moved).points - decode_strands(asset).points @ turn.T).max() < 1e-5
    assert anim.frames == 2 and anim.duration == pytest.approx(1 / 24)


def test_a_bad_animation_is_refused_with_what_is_wrong():
    asset = example_asset()
    anim = _turned(asset, [0.0, 0.2])
    anim.spine[1, 0, 0, 0] = np.nan
    with pytest.raises(AssetError, match="frame 1"):
        anim.validate(asset.cards)
    with pytest.raises(AssetError, match=r"\[F, C, M\+1, 3\]"):
        Animation(anim.spine[:, :2], anim.normal, 24.0).validate(asset.cards)
    with pytest.raises(AssetError, match="outside"):
        anim.cards(asset.cards, 2)


def test_turned_sh_seen_from_the_turned_direction_give_the_same_colour():
    rng = np.random.default_rng(3)
    sh = rng.normal(size=(40, 16, 3))
    turn = np.stack([axis_rotation(v / np.linalg.norm(v), a) for v, a in zip(rng.normal(size=(40, 3)),
                                                                           rng.uniform(0, 6, 40), strict=True)])
    view = rng.normal(size=(40, 3))
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    turned = rotate_sh(sh, turn)
    assert np.abs(sh_polynomial(turned, np.einsum("gij,gj->gi", turn, view)) - sh_polynomial(sh, view)).max() < 1e-12
    assert np.array_equal(turned[:, 0], sh[:, 0])


def test_segments_of_rigidly_turned_cards_turn_with_them_and_so_do_their_sh():
    asset = example_asset()
    anim = _turned(asset, [0.0, 0.7])
    turn = axis_rotation(np.array([0.0, 1.0, 0.0]), 0.7)
    assert np.abs(segment_rotations(asset, anim, 1) - turn).max() < 1e-5
    rest, moved = decode_gaussians(asset), frame_gaussians(asset, anim, 1)
    expected = rotate_sh(rest.sh, turn)
    assert np.abs(moved.sh - expected).max() < 1e-4 * np.abs(expected).max()
    assert np.array_equal(frame_gaussians(asset, anim, 1, turn_sh=False).sh, rest.sh)
    assert np.abs(frame_gaussians(asset, anim, 0).sh - rest.sh).max() < 1e-6
