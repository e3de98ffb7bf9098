"""A tiny training run: the loss goes down, checkpoints resume exactly, the .cgh is written."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from cghair_format import read
from training.config import ConfigError, TrainConfig
from training.datasets.read import read_dataset
from training.evaluate import evaluate, evaluate_model
from training.model import HairModel
from training.schedule import view_at
from training.splatter import DeviceError
from training.train import TrainError, base_asset, load_checkpoint, mean_hair_colour, train


def _tiny_config(**kw) -> TrainConfig:
    base = dict(iterations=60, n_cards=12, n_groups=3, points_per_strand=8, card_segments=6,
                codebook_size=4, latent_dim=16, mlp_hidden=[32], sh_degree=1, geometry_frozen_iters=30,
                log_every=10, checkpoint_every=1000, lr_mlp=5e-3, lr_codebook=5e-3)
    base.update(kw)
    return TrainConfig(**base)


def test_training_lowers_the_loss_and_writes_a_cgh(tiny, tmp_path):
    root, strands = tiny
    cfg = _tiny_config()
    ds = read_dataset(root / "ds")
    base = base_asset(cfg, strands, progress=False)
    before = evaluate_model(HairModel(base, cfg, mean_hair_colour(ds.train)), ds.train, "soft", 1.0)
    out = tmp_path / "hair.cgh"
    result = train(ds, cards=base, out=out, config=cfg, progress=False, threads=1)
    after = evaluate_model(result.model, ds.train, "soft", 0.1)
    assert after.psnr > before.psnr + 1.0, (before.psnr, after.psnr)
    assert result.history[-1]["loss"] < result.history[0]["loss"]
    assert out.is_file() and result.weight_mode in ("hard", "soft")
    asset = read(out)
    assert asset.metadata["training"]["config"]["iterations"] == 60
    assert asset.generator == "cghair train"
    summary = json.loads(out.with_suffix(".train.json").read_text())
    assert summary["config"]["variant"] == "latents" and summary["iterations_run"] == 60
    # the written file, decoded by the codec, scores what the export probe measured (same views)
    ev = evaluate(out, ds, split="train", use_lpips=False)
    assert ev.psnr > before.psnr + 1.0
    # the geometry left the cards' solution only after the frozen phase, and only a little (the exported
    # asset in the model's strand order: the file stores strands card by card)
    moved = np.abs(result.asset.uvd - base.uvd).max()
    assert 0 < moved < 0.05


def test_a_variable_count_file_trains_on_its_real_segments(tiny, tmp_path):
    """Cards built on strands of their own point counts (spec 3): training renders the real Gaussians
    only (placeholder coordinates get no gradient) and writes a file of the same counts."""
    from cghair_format import decode_gaussians, write
    from cghair_format.cards import build_cards
    from cghair_format.strands import Strands

    root, strands = tiny
    full = strands.to_array()
    counts = np.random.default_rng(0).integers(4, full.shape[1] + 1, len(full))
    counts[0] = full.shape[1]
    cut = Strands(np.concatenate([x[:n] for x, n in zip(full, counts, strict=True)]),
                  np.concatenate([[0], np.cumsum(counts)]).astype(np.int64))
    cfg = _tiny_config(iterations=30, geometry_frozen_iters=10)
    base = build_cards(cut, n_cards=12, n_groups=3, segments=6, sh_degree=1, progress=False).asset
    src = tmp_path / "varied.cgh"
    write(base, src)
    out = tmp_path / "trained.cgh"
    result = train(read_dataset(root / "ds"), cards=src, out=out, config=cfg, progress=False, threads=1)
    model, base = result.model, result.base
    assert base.variable and model.n_gaussians == base.n_gaussians < base.n_strands * (base.points_per_strand - 1)
    assert all(np.isfinite(h["loss"]) for h in result.history)
    placeholders = torch.as_tensor(~base.real_points())
    assert torch.equal(model.uv.detach()[placeholders], torch.as_tensor(base.uvd[..., :2])[placeholders])
    assert not torch.equal(model.uv.detach(), torch.as_tensor(base.uvd[..., :2]))  # the real points moved
    trained = read(out)
    assert np.array_equal(np.sort(trained.counts), np.sort(counts))
    assert decode_gaussians(trained).count == base.n_gaussians


def test_resume_is_exact(tiny, tmp_path):
    root, _ = tiny
    cfg = _tiny_config(iterations=12, geometry_frozen_iters=4, log_every=4)
    ds = read_dataset(root / "ds")
    full = train(ds, strands=tiny[1], config=cfg, checkpoint=tmp_path / "a.pt", progress=False)
    half = train(ds, strands=tiny[1], config=cfg, checkpoint=tmp_path / "b.pt", progress=False, stop_at=6)
    assert half.asset is None and load_checkpoint(tmp_path / "b.pt")["iteration"] == 6
    assert load_checkpoint(tmp_path / "b.pt")["seconds"] == pytest.approx(half.seconds, abs=0.05)
    resumed = train(ds, resume=tmp_path / "b.pt", checkpoint=tmp_path / "b.pt", progress=False)
    assert resumed.iterations_run == 6
    # the run's own time, and the whole training's (both runs) where the summary keeps it
    summary = resumed.asset.metadata["training"]
    assert summary["seconds"] == round(resumed.seconds, 3)
    assert summary["seconds_total"] == pytest.approx(half.seconds + resumed.seconds, abs=0.05)
    for (name, a), (_, b) in zip(full.model.named_parameters(), resumed.model.named_parameters(), strict=True):
        assert torch.allclose(a, b, atol=1e-6), name
    assert [h["iteration"] for h in resumed.history] == [4, 8, 12]


def test_output_folders_are_created(tiny, tmp_path):
    root, strands = tiny
    out = tmp_path / "new" / "deeper" / "hair.cgh"
    train(root / "ds", strands=strands, out=out, config=_tiny_config(iterations=2), progress=False)
    assert out.is_file() and out.with_suffix(".ckpt.pt").is_file()


def test_view_order_is_a_permutation_per_epoch():
    seen = [view_at(3, i, 5) for i in range(10)]
    assert sorted(seen[:5]) == list(range(5)) and sorted(seen[5:]) == list(range(5))


def test_bad_inputs(tiny, tmp_path):
    root, _ = tiny
    with pytest.raises(TrainError, match="needs strands"):
        train(root / "ds", config=_tiny_config(), progress=False)
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(TrainError, match="not a readable training checkpoint"):
        train(root / "ds", resume=tmp_path / "bad.pt", progress=False)
    with pytest.raises(TrainError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.pt")
    with pytest.raises(DeviceError, match="unknown torch device"):
        train(root / "ds", strands=tiny[1], config=_tiny_config(), progress=False, device="gpu9")
    if not torch.cuda.is_available():
        with pytest.raises(DeviceError, match="no usable CUDA"):
            train(root / "ds", strands=tiny[1], config=_tiny_config(), progress=False, device="cuda")


def _strand_bytes(path) -> int:
    from cghair_format import read_info

    return sum(c["stored_bytes"] for c in read_info(path)["chunks"] if c["type"] in ("STRD", "CHLD"))


def test_geometry_rate_keeps_moved_strands_cheap_to_store(tiny, tmp_path):
    """With the strands moving fast, the rate term leaves a written file whose strand points take fewer
    bytes than the same run without it (measured on the file, as the writer codes it)."""
    root, strands = tiny
    ds = read_dataset(root / "ds")
    sizes = {}
    for w in (0.0, 1.0):
        cfg = _tiny_config(geometry_frozen_iters=10, lr_geometry=1e-3, geometry_rate=w)
        train(ds, strands=strands, out=tmp_path / f"w{w}.cgh", config=cfg, progress=False, threads=1)
        sizes[w] = _strand_bytes(tmp_path / f"w{w}.cgh")
    assert sizes[1.0] < 0.9 * sizes[0.0], sizes


def test_geometry_rate_resumes_exactly(tiny, tmp_path):
    """The rate weight is saved with the checkpoint's config and applies after a resume as before."""
    with pytest.raises(ConfigError, match="geometry_rate must be a number >= 0"):
        TrainConfig(geometry_rate=-0.1).validate()
    root, strands = tiny
    cfg = _tiny_config(iterations=12, geometry_frozen_iters=4, log_every=4, lr_geometry=1e-3, geometry_rate=0.5)
    ds = read_dataset(root / "ds")
    full = train(ds, strands=strands, config=cfg, checkpoint=tmp_path / "a.pt", progress=False)
    train(ds, strands=strands, config=cfg, checkpoint=tmp_path / "b.pt", progress=False, stop_at=6)
    assert load_checkpoint(tmp_path / "b.pt")["config"]["geometry_rate"] == 0.5
    resumed = train(ds, resume=tmp_path / "b.pt", checkpoint=tmp_path / "b.pt", progress=False)
    assert resumed.config.geometry_rate == 0.5
    assert torch.allclose(full.model.uv, resumed.model.uv, atol=1e-6)
    # and the term does act: without it the same run ends elsewhere
    plain = train(ds, strands=strands, config=_tiny_config(iterations=12, geometry_frozen_iters=4, log_every=4,
                                                           lr_geometry=1e-3), progress=False)
    assert not torch.allclose(full.model.uv, plain.model.uv, atol=1e-6)
