"""Training-step timings on this CPU at the issue's small config (a real model of ~2,000 strands x
32 points = ~64k Gaussians, 128 x 128 views). Reports figures; never asserts times.

The full 2,000-iteration measurement with a per-stage breakdown is ``python -m training.bench``.
"""

from __future__ import annotations

import pytest
from hairdata import hair_path

pytest.importorskip("torch", reason="the training benchmark needs torch (pip install 'cghair[training]')")



@pytest.fixture(scope="module")
def setup():
    import torch

    from cghair_format.exchange import load_strands
    from training.ablation import scaled_config
    from training.dataset import orbit_cameras
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
def test_training_step(benchmark, setup, geometry):
    import torch

    from training import losses
    from training.splatter import render

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
        out = render(*model("gumbel", 0.5, frozen), cam)
        loss = losses.image_loss(out.rgb, target, 0.2) + 0.1 * losses.l1(out.alpha, target[..., 0])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    benchmark.pedantic(step, rounds=10, iterations=1, warmup_rounds=2)
    benchmark.extra_info.update({"gaussians": model.n_strands * (model.n_points - 1),
                                 "torch_threads": torch.get_num_threads()})
