"""The training schedule: geometry frozen, then trained; appearance learning rates decaying."""

from __future__ import annotations

import pytest
import torch
from training_helpers import hair_cap

from training.config import TrainConfig
from training.model import HairModel, tau_at
from training.schedule import Schedule
from training.train import base_asset


def test_schedule_freezes_the_geometry_then_decays_the_appearance():
    cfg = TrainConfig(iterations=100, n_cards=6, n_groups=2, points_per_strand=6, card_segments=4, codebook_size=3,
                      latent_dim=8, mlp_hidden=[8], sh_degree=0, geometry_frozen_iters=40, lr_final_factor=0.1)
    model = HairModel(base_asset(cfg, hair_cap(30, 8, seed=3), progress=False), cfg)
    optimizer = torch.optim.Adam(model.param_groups(cfg, 2.0))
    start = {g["name"]: g["lr"] for g in optimizer.param_groups}
    schedule = Schedule(cfg, model, optimizer, n_views=7)

    def rates():
        return {g["name"]: g["lr"] for g in optimizer.param_groups}

    first = schedule.apply(0)
    assert not first.geometry_on and not model.uv.requires_grad and first.tau == tau_at(cfg, 0) == 1.0
    assert rates() == {**start, "uv": 0.0, "delta": 0.0}
    assert schedule.apply(40).geometry_on and model.uv.requires_grad and model.delta.requires_grad
    assert rates()["uv"] == start["uv"] and rates()["delta"] == start["delta"] == 2.0 * cfg.lr_geometry
    schedule.apply(100)
    for name in ("mlp", "codebook"):
        assert rates()[name] == pytest.approx(0.1 * start[name], rel=1e-12)
    assert rates()["opacity"] == start["opacity"] and rates()["logits"] == start["logits"]
    assert sorted(schedule.apply(i).view for i in range(7)) == list(range(7))  # every view once an epoch
