"""The torch hair model agrees with the numpy decoder: geometry, Gaussians and exported appearance."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from cghair_format import decode, decode_gaussians, encode
from cghair_format.examples import example_asset, with_point_counts
from cghair_format.gaussians import segment_frames
from cghair_format.geometry import strand_points
from training.config import ConfigError, TrainConfig
from training.model import ExportError, HairModel, segment_gaussians, tau_at

# float32 torch vs float64-then-float32 numpy on coordinates of order 0.3: a few ulps
POINT_TOL = 2e-6


def _config(variant="latents", sh_degree=1):
    return TrainConfig(variant=variant, codebook_size=4, latent_dim=8, mlp_hidden=[16], sh_degree=sh_degree)


def _perturbed(model: HairModel, seed=0):
    """Move every parameter off its initial value so the comparison is not of zeros."""
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name in ("uv", "delta"):
                p.add_(1e-3 * torch.randn(p.shape, generator=gen))
            else:
                p.add_(0.3 * torch.randn(p.shape, generator=gen))


def test_points_match_numpy_geometry():
    asset = example_asset(seed=1, sh_degree=1)
    model = HairModel(asset, _config())
    _perturbed(model)
    uvd = torch.cat([model.uv, model.delta[..., None]], -1).detach().numpy()
    ref = strand_points(asset.cards, asset.strand_card, uvd)
    assert np.abs(model.points().detach().numpy() - ref).max() <= POINT_TOL


def test_segment_gaussians_match_numpy():
    rng = np.random.default_rng(0)
    pts = np.cumsum(rng.normal(size=(5, 7, 3)), axis=1).astype(np.float32)
    pts[0, 3] = pts[0, 2]  # a zero-length segment
    pts[1, 1] = pts[1, 0] - np.array([0, 0, 0.5], np.float32)  # a segment along -z
    m, q, s = segment_frames(pts, 0.01)
    tm, tq, ts = (x.numpy() for x in segment_gaussians(torch.as_tensor(pts), 0.01))
    assert np.allclose(tm, m, atol=1e-6) and np.allclose(ts, s, atol=1e-6)
    assert np.allclose(tq, q, atol=1e-6)


@pytest.mark.parametrize("variant,mode,varied", [("latents", "soft", False), ("latents", "hard", False),
                                                 ("no-card-clustering", "soft", False), ("multi-sh", "hard", False),
                                                 ("latents", "soft", True), ("multi-sh", "hard", True)])
def test_export_decodes_to_the_model_gaussians(variant, mode, varied):
    """Also with strands of their own point counts: the model hands out their real segments only."""
    asset = example_asset(seed=2, sh_degree=1)
    asset = with_point_counts(asset, seed=4) if varied else asset
    model = HairModel(asset, _config(variant))
    _perturbed(model)
    tau = 0.5
    exported = model.to_asset(asset, mode, tau)
    assert np.array_equal(exported.counts, asset.counts) and model.n_gaussians == asset.n_gaussians
    for a in (exported, decode(encode(exported, "lossless")[0])):
        g = decode_gaussians(a)
        assert g.count == asset.n_gaussians
        with torch.no_grad():
            means, quats, scales, opac, sh = (x.numpy() for x in model(mode, tau))
        assert np.abs(g.means - means).max() <= POINT_TOL
        assert np.allclose(g.rotations, quats, atol=1e-5) and np.allclose(g.scales, scales, atol=1e-6)
        assert np.allclose(g.opacities, opac, atol=1e-7)
        # float32 MLP in numpy vs torch: summation order differs
        assert np.abs(g.sh - sh).max() <= 1e-5 * max(1.0, np.abs(sh).max())
        assert np.abs(sh).max() > 0.1  # a real comparison, not of zeros
    if variant == "no-card-clustering":
        assert exported.appearance.n_groups == 1


@pytest.mark.parametrize("variant", ["unique", "single-sh"])
def test_free_sh_variants_cannot_be_written(variant):
    asset = example_asset(seed=3, sh_degree=1)
    model = HairModel(asset, _config(variant))
    with pytest.raises(ExportError, match="cannot be written"):
        model.to_asset(asset)
    means, _, _, _, sh = model("soft", 1.0)
    assert sh.shape == (asset.n_gaussians, 4, 3) and means.shape == (asset.n_gaussians, 3)


def test_multi_sh_beyond_the_formats_latent_size_trains_but_is_not_written():
    """The paper's 100 points at SH degree 3 make multi-sh codebook entries of 99 x 48 = 4,752 values,
    over META's latent_dim limit (4096): the model trains and renders; export says why it cannot."""
    asset = example_asset(seed=3, strands=4, points=100, sh_degree=3)
    model = HairModel(asset, _config("multi-sh", sh_degree=3))
    assert "4752 values; the format allows 4096" in model.export_refusal()
    with pytest.raises(ExportError, match="4752 values"):
        model.to_asset(asset)
    assert model("soft", 1.0)[4].shape == (asset.n_gaussians, 16, 3)
    assert HairModel(asset, _config("latents", sh_degree=3)).export_refusal() is None


def test_appearance_sizes():
    asset = example_asset(seed=4, strands=64, points=16, sh_degree=1)  # 15 segments, 4 SH coeffs
    s, g = asset.n_strands, asset.n_gaussians
    out = 15 * 4 * 3
    n_t = int(asset.cards.group.max()) + 1
    sizes = {v: HairModel(asset, _config(v)).appearance_parameters() for v in
             ("latents", "unique", "single-sh", "multi-sh", "no-card-clustering")}
    mlp = 8 * 16 + 16 + 16 * out + out
    assert sizes["latents"] == s * 4 + n_t * 4 * 8 + mlp
    assert sizes["no-card-clustering"] == s * 4 + 4 * 8 + mlp
    assert sizes["unique"] == g * 4 * 3
    assert sizes["single-sh"] == s * 4 * 3
    assert sizes["multi-sh"] == s * 4 + n_t * 4 * out


def test_weights_modes():
    model = HairModel(example_asset(seed=5, sh_degree=1), _config())
    with torch.no_grad():
        model.logits.copy_(torch.randn(model.logits.shape))
    hard = model.weights("hard", 1.0)
    assert torch.all(hard.sum(-1) == 1) and torch.all(hard.argmax(-1) == model.logits.argmax(-1))
    assert torch.allclose(model.weights("soft", 0.5), torch.softmax(model.logits / 0.5, -1))
    g = model.weights("gumbel", 0.5)
    assert torch.allclose(g.sum(-1), torch.ones(len(g)))
    with pytest.raises(ValueError, match="weight mode"):
        model.weights("argmax", 1.0)


def test_config_round_trip_and_errors(tmp_path):
    cfg = TrainConfig(iterations=5, variant="multi-sh")
    cfg.save(tmp_path / "c.json")
    assert TrainConfig.load(tmp_path / "c.json") == cfg
    assert TrainConfig().iterations == 30_000 and TrainConfig().codebook_size == 10
    assert TrainConfig().latent_dim == 64 and TrainConfig().n_groups == 64
    assert TrainConfig().geometry_frozen_iters == 7_000
    with pytest.raises(ConfigError, match="unknown variant"):
        TrainConfig(variant="nope").validate()
    with pytest.raises(ConfigError, match="unknown config keys: bogus"):
        TrainConfig.from_dict({"bogus": 1})
    with pytest.raises(ConfigError, match="codebook_size"):
        TrainConfig(codebook_size=300).validate()
    cfg = TrainConfig(iterations=100, tau_start=1.0, tau_end=0.1)
    assert tau_at(cfg, 0) == 1.0 and abs(tau_at(cfg, 100) - 0.1) < 1e-12


@pytest.mark.parametrize("variant", ["latents", "no-card-clustering", "multi-sh", "single-sh", "unique"])
@pytest.mark.parametrize("varied", [False, True])
def test_sh_source_of_some_gaussians_is_those_rows_of_all(variant, varied):
    """What the native splatter asks for (a few Gaussians, any order) is what the full SH hold there,
    and gradients reach the same parameters; with strands of their own point counts the indices are
    among the real Gaussians."""
    asset = example_asset(seed=1, sh_degree=1)
    asset = with_point_counts(asset, seed=2) if varied else asset
    model = HairModel(asset, _config(variant))
    _perturbed(model)
    torch.manual_seed(0)
    source = model.sh_source("soft", 0.5)
    every = source(None)
    assert len(every) == asset.n_gaussians
    index = torch.randperm(len(every))[: len(every) // 3]
    some = source(index)
    assert some.shape == (len(index), *every.shape[1:])
    assert torch.allclose(some, every[index], rtol=1e-5, atol=1e-6)
    some.sum().backward()
    appearance = [p for name, p in model.named_parameters() if name not in ("uv", "delta", "opacity_logit")]
    assert appearance and all(p.grad is not None for p in appearance)


def test_segment_rows_kernel_matches_the_full_layer_with_gradients():
    """The compiled rows (training/_rows.pyx) against the full layer's rows: values and gradients
    of hidden, weight and bias, to float32 rounding of sums of 16-64 terms."""
    from training import model as model_module

    if model_module._rows is None:
        pytest.fail("training/_rows is not built: run `make venv`")
    gen = torch.Generator().manual_seed(3)
    segments, width, n_hidden, strands = 7, 12, 16, 50
    hidden = torch.randn(strands, n_hidden, generator=gen)
    weight = torch.randn(segments * width, n_hidden, generator=gen)
    bias = torch.randn(segments * width, generator=gen)
    index = torch.randperm(strands * segments, generator=gen)[:120]
    index = torch.cat([index, index[:5]])  # a row asked twice
    results = []
    for rows in (model_module.segment_rows, lambda h, w, b, i, s: F.linear(h, w, b).reshape(-1, width)[i]):
        params = [t.clone().requires_grad_(True) for t in (hidden, weight, bias)]
        out = rows(*params, index, segments)
        (out * torch.linspace(-1, 1, out.numel()).reshape(out.shape)).sum().backward()
        results.append([out.detach(), *(p.grad for p in params)])
    for mine, truth in zip(*results, strict=True):
        assert torch.allclose(mine, truth, rtol=1e-5, atol=1e-5)
