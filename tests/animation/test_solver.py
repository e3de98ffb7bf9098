"""The strand solver's passes, each alone, and whole simulations: lengths, energy, stability, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from head_helpers import sphere_mesh

from cghair_format.animation import Capsules, SolverSettings, StrandState, UnstableSimulation, mesh_field
from cghair_format.animation.solver import (
    collide,
    collide_field,
    global_shape,
    integrate,
    keep_lengths,
    local_shape,
    rotate_between,
    step,
    wind_accel,
)
from cghair_format.animation.tracks import axis_rotation


def hanging(strands: int = 3, points: int = 12, length: float = 0.3, seed: int = 0) -> np.ndarray:
    """Wavy strands hanging from roots on a small circle, ``[N, P, 3]``."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, points)
    out = np.zeros((strands, points, 3))
    for i in range(strands):
        a = 2 * np.pi * i / strands
        out[i, :, 0] = 0.05 * np.cos(a) + 0.01 * np.sin(8 * t + rng.uniform(0, 6))
        out[i, :, 2] = 0.05 * np.sin(a)
        out[i, :, 1] = -length * t
    return out


def test_rotate_between_takes_a_onto_b_and_keeps_lengths():
    rng = np.random.default_rng(1)
    a, b, v = (rng.normal(size=(50, 3)) for _ in range(3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    assert np.allclose(rotate_between(a, b, a), b, atol=1e-12)
    assert np.allclose(np.linalg.norm(rotate_between(a, b, v), axis=1), np.linalg.norm(v, axis=1))
    assert np.array_equal(rotate_between(a, -a, v), v)  # no smallest rotation: left as it is


def test_integrate_falls_as_verlet_does_and_keeps_the_root():
    state = StrandState.at_rest(hanging(1, 4))
    root = state.x[:, 0].copy()
    g, dt = np.array([0.0, -9.81, 0.0]), 0.01
    for _ in range(10):
        integrate(state, g, 0.0, dt)
    # Verlet from rest: x_n = x_0 + a dt^2 n (n + 1) / 2
    assert np.allclose(state.x[:, 1:] - state.rest[:, 1:], g * dt * dt * 55, atol=1e-12)
    assert np.array_equal(state.x[:, 0], root)


def test_keep_lengths_restores_every_segment_exactly():
    state = StrandState.at_rest(hanging())
    state.x[:, 1:] += np.random.default_rng(2).normal(scale=0.02, size=state.x[:, 1:].shape)
    keep_lengths(state)
    lengths = np.linalg.norm(np.diff(state.x, axis=1), axis=-1)
    assert np.abs(lengths - state.rest_length).max() < 1e-12


def test_global_and_local_shape_at_full_stiffness_give_the_rest_pose():
    rest = hanging()
    state = StrandState.at_rest(rest)
    state.x[:, 1:] += 0.05
    global_shape(state, rest, 1.0, rest.shape[1])
    assert np.allclose(state.x, rest)
    state.x[:, 1:] += 0.05
    local_shape(state, rest, 1.0)  # the root stays, so the whole strand goes back
    assert np.allclose(state.x, rest, atol=1e-12)


def test_local_shape_keeps_the_bend_of_a_turned_strand():
    rest = hanging(1)
    turn = axis_rotation(np.array([1.0, 0, 0]), 0.8)
    state = StrandState.at_rest(rest)
    state.x[...] = rest @ turn.T
    target = rest @ turn.T
    local_shape(state, target, 1.0)
    assert np.allclose(state.x, target, atol=1e-12)


def test_collide_pushes_points_out_of_a_capsule_and_leaves_the_others():
    state = StrandState.at_rest(np.array([[[0, 1.0, 0], [0.05, 0, 0], [0.5, 0, 0]]]))
    collide(state, Capsules(np.array([[0.0, -1, 0]]), np.array([[0.0, 1, 0]]), np.array([0.1])))
    assert np.allclose(state.x[0, 1], [0.1, 0, 0]) and np.allclose(state.x[0, 2], [0.5, 0, 0])
    assert np.allclose(state.x[0, 0], [0, 1.0, 0])  # the root rides the head


def test_collide_field_pushes_points_out_of_a_moved_sphere_mesh_and_leaves_the_others():
    radius, margin = 0.1, 0.002
    field = mesh_field(*sphere_mesh(radius, rings=24), np.full(3, -0.15), np.full(3, 0.15), 32, margin)
    local = np.random.default_rng(4).uniform(-0.14, 0.14, (40, 6, 3))  # in the head's rest frame
    rotation, translation = axis_rotation(np.array([0.6, 0.8, 0.0]), 0.9), np.array([0.3, -0.2, 0.05])
    state = StrandState.at_rest(local @ rotation.T + translation)
    before = state.x.copy()
    r = np.linalg.norm(local, axis=-1)
    hit = (r < radius + margin - 2e-3) & (np.arange(6) > 0)  # clearly inside the margin, roots aside
    clear = (r > radius + margin + 2e-3) & (np.arange(6) > 0)
    for _ in (1, 2):  # the solver runs the pass every substep: a point at the centre needs a second
        collide_field(state, field, rotation, translation)
        after = np.linalg.norm((state.x - translation) @ rotation, axis=-1)  # from the sphere's centre
        assert hit.sum() > 20 and (after[hit] > r[hit]).all()
    # out to the margin, within 1.5e-3 (the facets' chord error, 0.9e-3, and the trilinear error)
    assert np.abs(after[hit] - (radius + margin)).max() < 1.5e-3
    assert np.array_equal(state.x[:, 0], before[:, 0])  # roots ride the head, even inside it
    assert np.array_equal(state.x[clear], before[clear])


def test_wind_acts_across_segments_only():
    state = StrandState.at_rest(hanging(1, 5, seed=3) * [0, 1, 0])  # a straight strand along y
    a = wind_accel(state, np.array([0.0, 3.0, 0.0]))
    assert np.abs(a).max() < 1e-12
    assert np.allclose(wind_accel(state, np.array([2.0, 0, 0])), [2.0, 0, 0])


def test_settings_outside_the_stable_range_are_refused():
    for bad in (dict(damping=1.5), dict(local_stiffness=-0.1), dict(substeps=0), dict(wind=(np.nan, 0, 0)),
                dict(settle=-1.0)):
        with pytest.raises(UnstableSimulation):
            SolverSettings(**bad).check()


def _run(settings: SolverSettings, angle_per_step: float, steps: int, dt: float, rest=None) -> StrandState:
    rest = hanging() if rest is None else rest
    state = StrandState.at_rest(rest)
    up = np.array([0.0, 1.0, 0.0])
    for i in range(steps):
        rotation = axis_rotation(up, angle_per_step * i)
        step(state, settings, rotation, np.zeros(3), -9.81 * up, np.zeros(3), None, dt)
    return state


def test_energy_decays_when_the_head_stops():
    settings = SolverSettings()
    state = _run(settings, 0.05, 30, 1 / 120)  # a quick turn, then still
    speeds = []
    rotation = axis_rotation(np.array([0.0, 1, 0]), 0.05 * 29)
    for _ in range(600):
        step(state, settings, rotation, np.zeros(3), np.array([0, -9.81, 0]), np.zeros(3), None, 1 / 120)
        speeds.append(np.abs(state.x - state.x_prev).max())
    assert speeds[-1] < 1e-3 * speeds[0] and max(speeds[300:]) < speeds[0]


def test_stable_at_the_largest_time_step_under_violent_motion():
    settings = SolverSettings(substeps=1, damping=0.0)
    rest = hanging(8, 24, 0.5)
    state = _run(settings, 0.6, 300, 1 / 30, rest)  # a third of a turn each 30 Hz step
    lengths = np.linalg.norm(np.diff(state.x, axis=1), axis=-1)
    assert np.isfinite(state.x).all() and np.abs(lengths - state.rest_length).max() < 1e-9
    reach = np.linalg.norm(state.x - state.x[:, :1], axis=-1).max()
    assert reach <= state.rest_length.sum(1).max() + 1e-9


def test_a_non_finite_step_is_refused():
    state = StrandState.at_rest(hanging())
    with pytest.raises(UnstableSimulation):
        step(state, SolverSettings(), np.eye(3), np.zeros(3), np.array([0, np.inf, 0]), np.zeros(3), None, 0.01)
