"""Training-step timings on this CPU at the issue's small config (a real model of ~2,000 strands x
32 points = ~64k Gaussians, 128 x 128 views), and ``python -m training.bench`` end to end on tiny
configs. Reports figures; never asserts times.

The full 2,000-iteration measurement with a per-stage breakdown is ``python -m training.bench``.
"""

from __future__ import annotations

import json
import math

import pytest
from hairdata import hair_path

pytest.importorskip("torch", reason="the training benchmark needs torch (pip install 'cghair[training]')")

STAGES = ["model", "render", "loss", "backward", "step"]


def test_bench_small_config_reports_every_figure(tmp_path, capsys):
    from training import bench

    out = tmp_path / "small.json"
    assert bench.main(["--strands", str(hair_path("Bangs_100.hair")), "--iters", "4", "--views", "4", "--res", "16",
                       "--points", "6", "--n-cards", "8", "--threads", "1", "--backend", "reference",
                       "--work", str(tmp_path / "work"), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    run = report["run"]
    assert run["backend"] == "reference" and run["iterations"] == 4
    assert list(run["stage_ms_per_iteration"]) == STAGES
    assert run["ms_per_iteration"] == pytest.approx(sum(run["stage_ms_per_iteration"].values()), abs=0.5)
    assert run["peak_rss_gib"] > 0 and report["machine"]["gpu"] is None
    assert report["scene"]["strands"] == 100 and report["scene"]["res"] == 16
    assert math.isfinite(report["held_out"]["psnr"]) and report["held_out"]["views"] == 1
    text = capsys.readouterr().out
    assert "backend reference: 4 iterations" in text and "held-out: PSNR" in text and "load average at end" in text


def test_bench_paper_scale_path_on_a_reduced_recipe(tmp_path, monkeypatch, capsys):
    """The --paper-scale code path with the recipe's sizes shrunk (the real one needs minutes an iteration)."""
    from cghair_format import paper_scale
    from training import bench
    from training.backends import default_backend

    for name, value in {"STRANDS": 150, "POINTS": 8, "CARDS": 8, "GROUPS": 2, "K": 3, "D": 8, "HIDDEN": 16,
                        "SH_DEGREE": 1}.items():
        monkeypatch.setattr(paper_scale, name, value)
    out = tmp_path / "paper.json"
    argv = ["--paper-scale", "--strands", str(hair_path("Bangs_100.hair")), "--iters", "3", "--reference-iters", "1",
            "--views", "4", "--res", "16", "--threads", "1", "--work", str(tmp_path / "work"), "--json", str(out)]
    assert bench.main(argv) == 0
    report = json.loads(out.read_text())
    assert report["scene"]["strands"] == 150 and report["scene"]["points"] == 8 and report["scene"]["cards"] <= 8
    assert report["run"]["iterations"] == 3 and report["run"]["backend"] == default_backend("cpu")
    if report["run"]["backend"] != "reference":
        assert report["reference"]["iterations"] == 1 and report["speedup_over_reference"] > 0
    # a second run reuses the cached cards and dataset
    capsys.readouterr()
    assert bench.main(argv) == 0
    assert "dataset:" not in capsys.readouterr().out



@pytest.fixture(scope="module")
def setup():
    import torch

    from cghair_format.exchange import load_strands
    from training.ablation import scaled_config
    from training.datasets.cameras import orbit_cameras
    from training.model import HairModel
    from training.train import base_asset

    strands = load_strands(hair_path("Ratboy_mohawk.tfx"))
    cfg = scaled_config("latents", 2000, points_per_strand=32)
    base = base_asset(cfg, strands, progress=False)
    model = HairModel(base, cfg)
    cams = orbit_cameras(strands.points.astype("float64"), 8, 128, strands.up_axis)
    opt = torch.optim.Adam(model.param_groups(cfg, 1.0), eps=1e-15)
    target = torch.rand(128, 128, 3)
    return model, cams, opt, target


@pytest.mark.bench
@pytest.mark.slow
@pytest.mark.parametrize("geometry", ["frozen", "trained"])
@pytest.mark.parametrize("backend", ["reference", "native"])
def test_training_step(benchmark, setup, geometry, backend):
    import torch

    from training import losses
    from training.backends import renderer

    render = renderer(backend)
    model, cams, opt, target = setup
    model.set_geometry_trainable(geometry == "trained")
    frozen = None
    if geometry == "frozen":
        with torch.no_grad():
            frozen = model.gaussian_geometry()
    state = {"i": 0}

    def step():
        cam = cams[state["i"] % len(cams)]
        state["i"] += 1
        means, quats, scales = frozen if frozen is not None else model.gaussian_geometry()
        out = render(means, quats, scales, model.opacities().reshape(-1), model.sh_source("gumbel", 0.5), cam)
        loss = losses.image_loss(out.rgb, target, 0.2) + 0.1 * losses.l1(out.alpha, target[..., 0])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    benchmark.pedantic(step, rounds=10, iterations=1, warmup_rounds=2)
    benchmark.extra_info["rows"] = [{"scene": "Ratboy_mohawk.tfx, 32 points, 128 x 128", "backend": backend,
                                     "geometry": geometry,
                                     "gaussians": model.n_strands * (model.n_points - 1),
                                     "torch threads": torch.get_num_threads()}]
