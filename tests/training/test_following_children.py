"""Interpolated strands follow their guides while the geometry trains, and the file keeps them as children."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from test_train import _strand_bytes, _tiny_config
from training_helpers import hair_cap

import cghair_format as cgh
from cghair_format.profiles import get_profile
from cghair_format.strands import densify
from training.children import following_children
from training.config import ConfigError, TrainConfig
from training.datasets.read import read_dataset
from training.datasets.synthetic import render_dataset
from training.model import HairModel
from training.train import base_asset, train


@pytest.fixture(scope="module")
def dense(tmp_path_factory):
    """60 guides densified to 150 strands (90 children), their cards, and a tiny dataset of them."""
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("dense")
    strands = densify(hair_cap(60, 8, seed=2), 150, seed=0)  # 8 points, as the cards keep them
    render_dataset(strands, root / "ds", views=9, res=32, engine="splat")
    base = base_asset(_tiny_config(), strands, progress=False)
    return root, strands, base


def _children_in(path) -> int:
    return cgh.read_info(path)["quant"].get("children", 0)


def test_the_writers_children_are_found_and_put_back_on_their_blend(dense):
    _, _, base = dense
    follow = following_children(base, "compact")
    assert follow is not None and len(follow.child) >= 0.5 * 90
    assert following_children(base, "lossless") is None  # it stores every strand's points
    model = HairModel(base, _tiny_config())
    guides = np.setdiff1d(np.arange(base.n_strands), follow.child.numpy())
    with torch.no_grad():  # the guides move by a few tolerances; the children stay behind
        model.uv[guides] += 0.01
    before = cgh.encode(model.to_asset(base), "compact")[0]
    miss = follow.project(model.uv, model.delta)
    after = cgh.encode(model.to_asset(base), "compact")[0]
    tol = get_profile("compact").position_tolerance * cgh.decode_strands(cgh.decode(after)).bbox_diagonal()
    assert miss < 1e-2 * tol
    kept = [cgh.read_info(data)["quant"].get("children", 0) for data in (before, after)]
    assert kept[1] >= len(follow.child) > kept[0], kept


def test_training_keeps_the_children_and_free_children_does_not(dense, tmp_path):
    """With the strands moving fast, the file of a run whose children follow keeps them (and its strand
    bytes low); with ``children_follow`` off every strand moves on its own and is coded in full."""
    root, strands, _ = dense
    ds = read_dataset(root / "ds")
    for follow in (True, False):
        cfg = _tiny_config(geometry_frozen_iters=10, lr_geometry=1e-3, children_follow=follow)
        train(ds, strands=strands, out=tmp_path / f"{follow}.cgh", config=cfg, progress=False, threads=1)
    assert _children_in(tmp_path / "True.cgh") >= 45 > _children_in(tmp_path / "False.cgh")
    assert _strand_bytes(tmp_path / "True.cgh") < 0.8 * _strand_bytes(tmp_path / "False.cgh")
    with pytest.raises(ConfigError, match="children_follow must be true or false"):
        TrainConfig(children_follow="yes").validate()
