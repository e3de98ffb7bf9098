"""``python -m training.precision``: render PSNR of each profile and weight step against lossless."""

from __future__ import annotations

from training_helpers import hair_cap

import cghair_format as cgh
from cghair_format.cards import build_cards
from training.datasets.synthetic import render_dataset
from training.precision import main, measure, with_weight_step


def test_coarser_weights_and_profiles_cost_picture_quality(tmp_path, capsys):
    strands = hair_cap(60, 10, seed=2)
    asset = build_cards(strands, n_cards=8, n_groups=2, points=10, seed=0, progress=False).asset
    render_dataset(strands, tmp_path / "ds", views=5, res=24, engine="splat")  # 3 train, 1 val, 1 test
    from training.datasets.read import read_dataset

    views = read_dataset(tmp_path / "ds").split("test")
    rows = {r["what"]: r for r in measure(asset, views, steps=(0.02, 0.5), mlp_steps=(0.02, 2.0))}
    assert rows["high file"]["psnr"] > rows["compact file"]["psnr"] > 30
    assert rows["weight step 0.02 only"]["psnr"] > rows["weight step 0.5 only"]["psnr"]
    assert rows["MLP step 0.02 only"]["psnr"] > rows["MLP step 2 only"]["psnr"]
    assert rows["compact file"]["bytes"] < rows["high file"]["bytes"]
    # only the weights change
    coarse = with_weight_step(asset, 0.5)
    assert (coarse.uvd == asset.uvd).all() and (coarse.opacity == asset.opacity).all()
    assert not (coarse.appearance.mlp[-1].weight == asset.appearance.mlp[-1].weight).all()
    mlp_only = with_weight_step(asset, None, 0.5)  # the codebooks stay exact
    assert (mlp_only.appearance.codebooks == asset.appearance.codebooks).all()
    assert not (mlp_only.appearance.mlp[-1].weight == asset.appearance.mlp[-1].weight).all()

    cgh.write(asset, tmp_path / "ref.cgh", "lossless")
    assert main([str(tmp_path / "ref.cgh"), str(tmp_path / "ds"), "--weight-steps", "0.2", "--mlp-steps", "0.7"]) == 0
    out = capsys.readouterr().out
    assert "compact file" in out and "weight step 0.2 only" in out and "MLP step 0.7 only" in out
    assert "on 1 val views" in out  # settings are chosen on the validation views by default
    assert main([str(tmp_path / "missing.cgh"), str(tmp_path / "ds")]) == 1
    assert "error" in capsys.readouterr().err
