"""Geometry training that moves each strand by a smooth correction (training.smooth_moves)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from test_train import _strand_bytes, _tiny_config

from cghair_format.cards.guide import bspline_basis
from training.config import ConfigError, TrainConfig
from training.datasets.read import read_dataset
from training.model import HairModel
from training.smooth_moves import SmoothMoves
from training.train import base_asset, train


@pytest.fixture(scope="module")
def cap(tiny):
    """The tiny dataset's folder and strands, and their cards (8 points a strand)."""
    root, strands = tiny
    return root, strands, base_asset(_tiny_config(), strands, progress=False)


def _change(model: HairModel, base) -> torch.Tensor:
    now = torch.cat([model.uv, model.delta[..., None]], -1).detach()
    return now - torch.as_tensor(base.uvd.astype(np.float32))


def test_the_projection_keeps_smooth_changes_and_drops_zigzags(cap):
    _, _, base = cap
    model = HairModel(base, _tiny_config())
    p = base.points_per_strand
    t = torch.linspace(0, 1, p)
    smooth = 1e-3 * (0.5 - t + 2 * t**2 - t**3)  # a cubic: in every cubic B-spline's span
    zigzag = 1e-3 * (-1.0) ** torch.arange(p)
    with torch.no_grad():
        model.uv[:40, :, 0] += smooth
        model.delta[40:] += zigzag
    SmoothMoves(base, 4).project(model.uv, model.delta)
    change = _change(model, base)
    assert torch.allclose(change[:40, :, 0], smooth.expand(40, p), atol=1e-6)
    assert change[:40, :, 1:].abs().max() < 1e-6
    # the zigzag's fit by four coefficients keeps a fraction of it (the ends, which the basis pins)
    assert change[40:, :, 2].norm() < 0.5 * zigzag.expand(40, p).norm()


def test_children_and_points_past_a_strands_count_are_left_alone(cap):
    _, _, base = cap
    counts = np.full(base.n_strands, base.points_per_strand, np.int32)
    counts[::2] = 5  # half the strands end early: their last points are padding
    short = dataclasses.replace(base, point_counts=counts)
    model = HairModel(base, _tiny_config())
    zigzag = 1e-3 * (-1.0) ** torch.arange(base.points_per_strand)
    with torch.no_grad():
        model.uv[..., 1] += zigzag
    moves = SmoothMoves(short, 3, skip=torch.arange(0, 10))
    assert sorted(group[1] for group in moves.groups) == [5, base.points_per_strand]
    before = model.uv.detach().clone()
    moves.project(model.uv, model.delta)
    assert torch.equal(model.uv[:10], before[:10])  # the children: their own projection's
    assert torch.equal(model.uv[10::2, 5:], before[10::2, 5:])  # padding untouched
    assert not torch.equal(model.uv[10:, :5], before[10:, :5])
    change = _change(model, base)[..., 1]
    for rows, count in ((slice(10, None, 2), 5), (slice(11, None, 2), base.points_per_strand)):
        basis = bspline_basis(np.linspace(0, 1, count), 3)
        c = change[rows, :count].numpy()
        resid = c - c @ (basis @ np.linalg.pinv(basis)).T
        assert np.abs(resid).max() < 1e-6  # what is left is in the span of the count's own basis


def test_smooth_moves_keep_moved_strands_cheap_to_store(cap, tmp_path):
    """With the strands moving fast, what moving them adds to the written file's strand bytes (over the
    same run with frozen geometry) is much less when the moves are smooth than when every point moves on
    its own (measured on the written files: 250 against 480 bytes when this was written)."""
    root, strands, _ = cap
    ds = read_dataset(root / "ds")
    sizes = {}
    for name, kw in (("frozen", dict(geometry_frozen_iters=60)), ("free", dict(geometry_frozen_iters=10)),
                     ("smooth", dict(geometry_frozen_iters=10, geometry_controls=2))):
        cfg = _tiny_config(lr_geometry=1e-3, **kw)
        train(ds, strands=strands, out=tmp_path / f"{name}.cgh", config=cfg, progress=False, threads=1)
        sizes[name] = _strand_bytes(tmp_path / f"{name}.cgh")
    assert sizes["smooth"] - sizes["frozen"] < 0.7 * (sizes["free"] - sizes["frozen"]), sizes
    for bad in (-1, 2.5, True):
        with pytest.raises(ConfigError, match="geometry_controls must be an integer >= 0"):
            TrainConfig(geometry_controls=bad).validate()


def test_smooth_moves_resume_exactly(cap, tmp_path):
    """The controls are saved with the checkpoint's config, and a resumed run projects onto the same start."""
    from training.train import load_checkpoint

    root, strands, _ = cap
    ds = read_dataset(root / "ds")
    cfg = _tiny_config(iterations=12, geometry_frozen_iters=4, log_every=4, lr_geometry=1e-3, geometry_controls=3)
    full = train(ds, strands=strands, config=cfg, checkpoint=tmp_path / "a.pt", progress=False, threads=1)
    train(ds, strands=strands, config=cfg, checkpoint=tmp_path / "b.pt", progress=False, threads=1, stop_at=6)
    assert load_checkpoint(tmp_path / "b.pt")["config"]["geometry_controls"] == 3
    resumed = train(ds, resume=tmp_path / "b.pt", checkpoint=tmp_path / "b.pt", progress=False, threads=1)
    assert torch.allclose(full.model.uv, resumed.model.uv, atol=1e-6)
