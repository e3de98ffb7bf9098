"""The render-dataset, train and eval verbs end to end on a tiny scene, and their bad-input errors."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from cghair_format.cli import main


def test_render_train_eval(tmp_path, strands_file, capsys):
    ds = tmp_path / "ds"
    assert main(["render-dataset", str(strands_file), "-o", str(ds), "--views", "8", "--res", "24",
                 "--no-progress"]) == 0
    assert "6 train + 1 val + 1 test views" in capsys.readouterr().out
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({"codebook_size": 4, "latent_dim": 8, "mlp_hidden": [16], "sh_degree": 1,
                               "card_segments": 4, "log_every": 5}))
    out = tmp_path / "hair.cgh"
    assert main(["train", str(ds), "--strands", str(strands_file), "-o", str(out), "--iters", "10",
                 "--config", str(cfg), "--n-cards", "8", "--groups", "2", "--points", "6", "--no-progress",
                 "--threads", "1", "--backend", "reference"]) == 0
    text = capsys.readouterr().out
    assert "iteration 10" in text and f"wrote {out}" in text and "backend reference" in text
    assert json.loads(out.with_suffix(".train.json").read_text())["backend"] == "reference"
    assert out.is_file() and out.with_suffix(".ckpt.pt").is_file()
    assert main(["train", str(ds), "--resume", str(out.with_suffix(".ckpt.pt")), "-o", str(out), "--iters", "15",
                 "--no-progress", "--threads", "1"]) == 0
    assert "5 iterations this run" in capsys.readouterr().out
    # a .cgh with cards is a valid starting point too (its cards and strand coordinates are kept)
    out2 = tmp_path / "again.cgh"
    assert main(["train", str(ds), "--cards", str(out), "-o", str(out2), "--iters", "3", "--config", str(cfg),
                 "--no-progress", "--threads", "1", "--point-tolerance", "2e-3"]) == 0
    assert "points: within 0.002 of the bbox diagonal" in capsys.readouterr().out
    from cghair_format import read, read_info

    first, second = read(out), read(out2)
    assert second.cards.count == first.cards.count and second.uvd.shape == first.uvd.shape
    assert read_info(out2)["points_within"] == 2e-3 and read_info(out)["points_within"] == 2e-4
    capsys.readouterr()
    assert main(["eval", str(out), str(ds), "--out", str(tmp_path / "ev"), "--threads", "1",
                 "--backend", "reference"]) == 0
    text = capsys.readouterr().out
    assert "PSNR" in text and "LPIPS" in text
    assert (tmp_path / "ev" / "metrics.json").is_file()
    assert len(list((tmp_path / "ev").glob("*_gt_render_diff.png"))) == 1


def test_geometry_frozen_iters_flag(tmp_path, strands_file):
    import argparse

    from training.cli_train import _config, add_arguments

    p = argparse.ArgumentParser()
    add_arguments(p)
    assert _config(p.parse_args(["DS", "-o", "x.cgh", "--iters", "300"])).geometry_frozen_iters == 70
    assert _config(p.parse_args(["DS", "-o", "x.cgh", "--iters", "300",
                                 "--geometry-frozen-iters", "300"])).geometry_frozen_iters == 300
    assert _config(p.parse_args(["DS", "-o", "x.cgh"])).geometry_rate == 0
    assert _config(p.parse_args(["DS", "-o", "x.cgh", "--geometry-rate", "0.1"])).geometry_rate == 0.1
    assert _config(p.parse_args(["DS", "-o", "x.cgh"])).geometry_controls == 0
    assert _config(p.parse_args(["DS", "-o", "x.cgh", "--geometry-controls", "12"])).geometry_controls == 12
    # frozen for the whole run, the strands come out exactly as they went in
    ds = tmp_path / "ds"
    assert main(["render-dataset", str(strands_file), "-o", str(ds), "--views", "4", "--res", "16",
                 "--no-progress"]) == 0
    common = ["--iters", "4", "--n-cards", "6", "--groups", "2", "--points", "5", "--no-progress", "--threads", "1",
              "--profile", "lossless"]
    moved, kept = tmp_path / "moved.cgh", tmp_path / "kept.cgh"
    assert main(["train", str(ds), "--strands", str(strands_file), "-o", str(moved), *common,
                 "--geometry-frozen-iters", "0"]) == 0
    assert main(["train", str(ds), "--cards", str(moved), "-o", str(kept), *common,
                 "--geometry-frozen-iters", "4"]) == 0
    from cghair_format import read

    assert np.array_equal(read(kept).uvd, read(moved).uvd)
    assert main(["train", str(ds), "--cards", str(kept), "-o", str(moved), *common,
                 "--geometry-frozen-iters", "0"]) == 0
    assert not np.array_equal(read(kept).uvd, read(moved).uvd)


def test_opacity_budget_in_train_and_encode(tmp_path, strands_file, capsys, monkeypatch):
    """cgh train --opacity-budget 0 keeps every opacity within the profile's bound; the default lowers
    the least used where that codes smaller, and then the file says so, the summary counts them and the
    export PSNR is the written file's; cgh encode --views stores them lower, in fewer bytes (on opacities
    as varied as a long run's: a few iterations leave them smooth, and the writer keeps those as they are)."""
    from cghair_format import read, read_info, write

    ds = tmp_path / "ds"
    assert main(["render-dataset", str(strands_file), "-o", str(ds), "--views", "6", "--res", "24",
                 "--no-progress"]) == 0
    common = ["--iters", "6", "--n-cards", "8", "--groups", "2", "--points", "8", "--no-progress", "--threads", "1"]
    kept, lowered, default = tmp_path / "kept.cgh", tmp_path / "lowered.cgh", tmp_path / "default.cgh"
    assert main(["train", str(ds), "--strands", str(strands_file), "-o", str(kept), *common,
                 "--opacity-budget", "0"]) == 0
    out = capsys.readouterr().out
    assert "opacities: all within 1/15 of the writer's input" in out
    mlp = read_info(kept)["mlp_weights"]
    assert f"MLP 64->64->{7 * 16 * 3}: {mlp['values']:,} weights and biases in {mlp['stored_bytes']:,} bytes" in out
    assert json.loads(kept.with_suffix(".train.json").read_text())["negligible_segments"] is None
    varied = read(kept)
    varied.opacity = np.random.default_rng(0).uniform(0, 1, varied.opacity.shape).astype(np.float32)
    write(varied, kept)
    assert main(["train", str(ds), "--cards", str(kept), "-o", str(default), *common, "--iters", "1"]) == 0
    summary = json.loads(default.with_suffix(".train.json").read_text())
    opacities = read_info(default)["opacities"]
    assert summary["negligible_segments"] > 0 and opacities["lowered"] > 0 and opacities["budget"] == 0.1
    out = capsys.readouterr().out
    assert f"export PSNR {summary['export_psnr'][summary['weight_mode']]:.2f} dB, this file as decoded" in out
    assert f"opacities: {opacities['lowered']:,} of " in out
    assert _probe_psnr(default, ds, summary) == pytest.approx(summary["export_psnr"][summary["weight_mode"]], abs=1e-4)
    capsys.readouterr()
    assert main(["encode", str(kept), "-o", str(lowered), "--views", str(ds), "--opacity-budget", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "Gaussians carry 0.2 of the blend weight" in out and "kept the marked stream" in out
    size = {p: {c["type"]: c["stored_bytes"] for c in read_info(p)["chunks"]}["OPAC"] for p in (kept, lowered)}
    assert size[lowered] < size[kept] and f"OPAC {size[lowered]:,} bytes with the marks, {size[kept]:,} without" in out
    before, after = read(kept), read(lowered)
    assert after.opacity.sum() < 0.8 * before.opacity.sum() and after.n_gaussians == before.n_gaussians
    assert read_info(lowered)["opacities"]["budget"] == 0.2
    for argv, message in ((["--opacity-budget", "0.1"], "--opacity-budget needs --views"),
                          (["--views", str(ds), "--profile", "lossless"], "choose a quantized --profile")):
        assert main(["encode", str(kept), "-o", str(tmp_path / "x.cgh"), *argv]) == 2
        assert message in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "training.visibility", None)  # as if torch were not installed
    assert main(["encode", str(kept), "-o", str(tmp_path / "x.cgh"), "--views", str(ds)]) == 2
    assert "pip install 'cghair[training]'" in capsys.readouterr().err


def _probe_psnr(path, dataset, summary) -> float:
    """The PSNR of the file at ``path``, decoded, on the training views the export probe renders."""
    import torch

    from cghair_format import decode_gaussians, read
    from training import losses
    from training.backends import render_gaussians
    from training.datasets.read import read_dataset
    from training.train import EXPORT_PROBE_VIEWS, _targets

    views = read_dataset(dataset).train
    probe = views[:: max(1, len(views) // EXPORT_PROBE_VIEWS)][:EXPORT_PROBE_VIEWS]
    background = tuple(summary["config"]["background"])
    g = decode_gaussians(read(path))
    rgbs = [render_gaussians(g, v.camera, background, "cpu", summary["backend"])["rgb"] for v in probe]
    return losses.psnr(torch.as_tensor(np.stack(rgbs)), _targets(probe, background)[0])


@pytest.mark.parametrize("profile", ["high", "compact"])
def test_opacity_budget_0_keeps_every_opacity_within_the_profiles_bound(tmp_path, strands_file, profile):
    """With --opacity-budget 0 no opacity is lowered: every one in the decoded file lies within the
    profile's bound of the trained model's, for each quantized profile."""
    import cghair_format as cgh
    from training.config import TrainConfig
    from training.train import train

    ds, cards = tmp_path / "ds", tmp_path / "cards.cgh"
    assert main(["render-dataset", str(strands_file), "-o", str(ds), "--views", "4", "--res", "16",
                 "--no-progress"]) == 0
    assert main(["cards", str(strands_file), "-o", str(cards), "--cards", "6", "--groups", "2", "--points", "6"]) == 0
    varied = cgh.read(cards)
    varied.opacity = np.random.default_rng(1).uniform(0.05, 0.95, varied.opacity.shape).astype(np.float32)
    cgh.write(varied, cards)
    config = TrainConfig(iterations=2, codebook_size=2, latent_dim=4, mlp_hidden=[8], sh_degree=0,
                         geometry_frozen_iters=2, opacity_budget=0.0)
    out = tmp_path / "trained.cgh"
    result = train(ds, cards=cards, out=out, config=config, profile=profile, progress=False, threads=1)
    own = cgh.encode(result.asset, profile)[1].in_file_order(result.asset).opacity  # (the writer is deterministic)
    assert np.abs(cgh.read(out).opacity - own).max() <= cgh.PROFILES[profile].opacity_tolerance + 1e-7
    assert cgh.read_info(out)["opacities"]["lowered"] is None


def test_unique_variant_writes_no_cgh(tmp_path, strands_file, capsys):
    ds = tmp_path / "ds"
    assert main(["render-dataset", str(strands_file), "-o", str(ds), "--views", "4", "--res", "16",
                 "--no-progress"]) == 0
    out = tmp_path / "u.cgh"
    assert main(["train", str(ds), "--strands", str(strands_file), "-o", str(out), "--iters", "3",
                 "--variant", "unique", "--n-cards", "6", "--groups", "2", "--points", "5", "--no-progress"]) == 0
    assert "no .cgh written: variant 'unique' stores free SH" in capsys.readouterr().err
    assert not out.exists() and out.with_suffix(".train.json").is_file()


@pytest.mark.parametrize("argv,message", [
    (["train", "DS", "-o", "x.cgh"], "give --strands"),
    (["train", "MISSING", "--strands", "S", "-o", "x.cgh"], "does not exist"),
    (["eval", "NOTCGH", "DS"], "not a .cgh file"),
    (["eval", "NOTCGH", "DS", "--device", "gpu9"], "unknown torch device 'gpu9'"),
    (["render-dataset", "S", "-o", "OUT", "--views", "4", "--res", "8", "--device", "gpu9"],
     "unknown torch device 'gpu9'"),
    (["render-dataset", "S", "-o", "OUT", "--engine", "splat", "--views", "4", "--preset", "red",
      "--thickness", "0.01", "--res", "8"], None),
    (["render-dataset", "S", "-o", "OUT", "--views", "4", "--res", "8", "--backend", "reference"], None),
    (["train", "DS", "--strands", "S", "-o", "x.cgh", "--backend", "gsplat"],
     "the gsplat backend runs on CUDA, not cpu; use --device cuda"),
    (["eval", "NOTCGH", "DS", "--backend", "gsplat"], "the gsplat backend runs on CUDA"),
    (["train", "DS", "--strands", "S", "-o", "x.cgh", "--profile", "lossless", "--point-tolerance", "1e-3"],
     "--point-tolerance: profile 'lossless' stores points exactly"),
    (["render-dataset", "S", "-o", "OUT", "--views", "4", "--res", "8", "--backend", "native"],
     "the native backend is not built"),
])
def test_bad_inputs_give_clear_errors(tmp_path, strands_file, capsys, monkeypatch, argv, message):
    monkeypatch.setitem(sys.modules, "training._raster", None)  # as if the native extension were not built
    ds = tmp_path / "ds"
    ds.mkdir()
    (tmp_path / "notcgh").write_text("hello")
    subst = {"DS": str(ds), "MISSING": str(tmp_path / "missing"), "S": str(strands_file),
             "NOTCGH": str(tmp_path / "notcgh"), "OUT": str(tmp_path / "out"), "x.cgh": str(tmp_path / "x.cgh")}
    code = main([subst.get(a, a) for a in argv])
    if message is None:
        assert code == 0
    else:
        assert code == 2 and message in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["render-dataset", "s", "-o", "d", "--views", "1"],
                                  ["render-dataset", "s", "-o", "d", "--engine", "mitsuba"],
                                  ["train", "d", "-o", "x.cgh", "--variant", "bogus"],
                                  ["train", "d", "-o", "x.cgh", "--iters", "0"],
                                  ["train", "d", "-o", "x.cgh", "--backend", "vulkan"],
                                  ["train", "d", "-o", "x.cgh", "--opacity-budget", "1"],
                                  ["train", "d", "-o", "x.cgh", "--geometry-rate", "-1"],
                                  ["train", "d", "-o", "x.cgh", "--geometry-controls", "-1"],
                                  ["train", "d", "-o", "x.cgh", "--point-tolerance", "0.02"],
                                  ["encode", "f.cgh", "-o", "x.cgh", "--opacity-budget", "-0.1"],
                                  ["eval", "f.cgh", "d", "--backend", "vulkan"],
                                  ["train", "d", "--strands", "a", "--cards", "b", "-o", "x.cgh"]])
def test_usage_errors(argv):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
