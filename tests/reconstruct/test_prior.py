"""The strand shape prior: the shipped basis, frame invariance, projection, the fit command."""

import numpy as np
import pytest
import torch
from hairdata import hair_path

from cghair_format.cli import main
from cghair_format.strands import resample
from cghair_format.synth import synthesize
from training.reconstruct.prior import BUILTIN, StrandPrior, fit_builtin, project, residual
from training.reconstruct.refine import _prior_loss

UP = np.array([0.0, 1.0, 0.0])


@pytest.mark.slow
def test_shipped_basis_is_the_builtin_fit():
    shipped, fresh = StrandPrior.load(BUILTIN), fit_builtin()
    assert shipped.sources == fresh.sources and all(s.startswith("synth:") for s in shipped.sources)
    np.testing.assert_allclose(shipped.stddev, fresh.stddev, rtol=1e-4)
    # components are defined up to sign
    np.testing.assert_allclose(np.abs((shipped.components * fresh.components).sum(1)), 1.0, atol=1e-4)


def _arr(style, seed, n=300):
    return resample(synthesize(style, n_strands=n, n_points=32, seed=seed), 32).to_array().astype(np.float64)


def test_unseen_synthetic_strands_are_near_the_basis():
    prior = StrandPrior.load()
    r = residual(_arr("straight", 123), prior, UP)
    assert np.median(r) < 0.003  # 3 mm RMS per point on 35 cm strands
    # a strand folded back on itself every few points is far from it
    zigzag = np.zeros((1, 32, 3))
    zigzag[0, :, 0] = np.arange(32) * 0.01
    zigzag[0, 1::2, 1] = 0.02
    assert residual(zigzag, prior, UP)[0] > 3 * np.median(r)


def test_residual_ignores_placement_and_heading():
    prior = StrandPrior.load()
    a = _arr("wavy", 5, 50)
    c, s = np.cos(0.7), np.sin(0.7)
    about_up = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    b = a @ about_up.T + np.array([0.3, -0.2, 0.1])
    np.testing.assert_allclose(residual(a, prior, UP), residual(b, prior, UP), atol=1e-9)


def test_projection_and_torch_loss_agree_with_the_residual():
    prior = StrandPrior.load()
    s = synthesize("curly", n_strands=40, n_points=32, seed=11)
    p = project(s, prior, UP)
    assert np.median(residual(p.to_array().astype(np.float64), prior, UP)) < 1e-4  # in the span now
    np.testing.assert_allclose(p.to_array()[:, 0], s.to_array()[:, 0], atol=1e-6)  # roots kept
    pts = torch.tensor(s.to_array(), dtype=torch.float64, requires_grad=True)
    loss = _prior_loss(pts, prior, UP, 1.0)
    expected = (residual(s.to_array().astype(np.float64), prior, UP) ** 2).mean()
    assert float(loss.detach()) == pytest.approx(expected, rel=0.05)  # mean of squares vs square of per-strand RMS
    loss.backward()
    assert torch.isfinite(pts.grad).all() and pts.grad.abs().sum() > 0


def test_fit_command_excludes_held_out_models(tmp_path, capsys):
    a, b = hair_path("ruby_long_hair_16_guide.tfx"), hair_path("Ratboy_mohawk.tfx")
    out = tmp_path / "prior.npz"
    assert main(["fit-strand-prior", str(a), str(b), "-o", str(out), "--exclude", b.name,
                 "--components", "8"]) == 0
    prior = StrandPrior.load(out)
    assert prior.sources == [a.name] and prior.components.shape == (8, 96)
    assert main(["fit-strand-prior", str(b), "-o", str(out), "--exclude", b.name]) == 2
    assert "nothing to fit" in capsys.readouterr().err
