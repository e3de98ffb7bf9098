"""The backend registry, its messages, the gsplat adapter's argument conversion and, where CUDA is
present, gsplat against the reference splatter."""

from __future__ import annotations

import importlib
import math
import sys
import types

import numpy as np
import pytest
import torch

from cghair_format.camera import Camera
from cghair_format.gaussians import SH_C0
from training import backends, splatter
from training.backends import BackendError
from training.datasets.synthetic import default_thickness, reference_gaussians


def _native_built() -> bool:
    try:
        importlib.import_module("training._raster")
        return True
    except ImportError:
        return False


def random_scene(n: int, seed: int, deg: int = 3, dtype=torch.float32):
    gen = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=gen, dtype=dtype) - 0.5) * 1.2
    quats = torch.randn(n, 4, generator=gen, dtype=dtype)
    scales = 0.02 + 0.12 * torch.rand(n, 3, generator=gen, dtype=dtype)
    opac = 0.3 + 0.6 * torch.rand(n, generator=gen, dtype=dtype)
    sh = 0.5 * torch.randn(n, (deg + 1) ** 2, 3, generator=gen, dtype=dtype)
    return means, quats, scales, opac, sh


def hair_scene(strands):
    """Thin segment Gaussians of the procedural hair cap (the splat engine's ground truth)."""
    g = reference_gaussians(strands, default_thickness(strands), sh_degree=3)
    return tuple(torch.as_tensor(np.ascontiguousarray(a, np.float32))
                 for a in (g.means, g.rotations, g.scales, g.opacities, g.sh))


def camera(res: int = 48, az: float = 30.0) -> Camera:
    return Camera.orbit((0, 0, 0), 3.0, az, 15.0, res, res, fov_y_deg=45.0)


# --- registry and messages ---------------------------------------------------------------------------------


def test_reference_is_always_available():
    assert backends.available_backends("cpu")[0] == "reference"
    assert backends.check_backend("reference", "cpu") == "reference"
    assert backends.resolve_backend("reference", "cpu") == "reference"


def test_default_backend_on_cpu():
    assert backends.default_backend("cpu") == ("native" if _native_built() else "reference")
    assert backends.resolve_backend(None, "cpu") == backends.default_backend("cpu")


def test_unknown_backend():
    with pytest.raises(BackendError, match="unknown backend 'vulkan'; choose one of reference, native, gsplat"):
        backends.check_backend("vulkan")


def test_native_not_built_says_how_to_build(monkeypatch):
    monkeypatch.setitem(sys.modules, "training._raster", None)  # an import of it now fails
    with pytest.raises(BackendError, match=r"native backend is not built .*python setup.py build_ext --inplace"):
        backends.check_backend("native", "cpu")
    assert "native" not in backends.available_backends("cpu")
    assert backends.default_backend("cpu") == "reference"


def test_native_is_cpu_only(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    with pytest.raises(BackendError, match="runs on the CPU, not cuda"):
        backends.check_backend("native", "cuda")


def test_gsplat_on_cpu_says_use_cuda():
    with pytest.raises(BackendError, match="gsplat backend runs on CUDA, not cpu; use --device cuda"):
        backends.check_backend("gsplat", "cpu")
    assert "gsplat" not in backends.available_backends("cpu")


def test_gsplat_without_cuda(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(BackendError, match="needs a CUDA device and this torch has none"):
        backends.render("gsplat", *random_scene(3, 0), camera())


def test_gsplat_missing_package_says_what_to_install(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setitem(sys.modules, "gsplat", None)
    with pytest.raises(BackendError, match=r"needs the gsplat package: pip install 'cghair\[cuda\]'"):
        backends.renderer("gsplat")(*random_scene(3, 0), camera())


def _gsplat_import_fails(monkeypatch, error: Exception) -> None:
    """As on a CUDA machine whose installed gsplat raises ``error`` (not ImportError) when imported."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    real_import = importlib.import_module

    def import_module(name, *args):
        if name == "gsplat":
            raise error
        return real_import(name, *args)

    monkeypatch.setattr(importlib, "import_module", import_module)


def test_gsplat_that_breaks_on_import_says_why(monkeypatch):
    """An installed gsplat whose import fails with anything but ImportError (a CUDA library or torch ABI
    mismatch) is a BackendError naming the cause, so `cgh train --device cuda` says why."""
    _gsplat_import_fails(monkeypatch, OSError("libcudart.so.12: cannot open shared object file"))
    with pytest.raises(BackendError, match=r"gsplat is installed but fails to import \(OSError: libcudart.so.12"):
        backends.check_backend("gsplat", "cuda")
    assert backends.default_backend("cuda") == "reference"


@pytest.mark.parametrize("backend_args,message", [
    (["--backend", "gsplat"], "error: gsplat is installed but fails to import (RuntimeError: CUDA driver too old)"),
    ([], "note: training with the reference backend, not gsplat: gsplat is installed but fails to import"),
])
def test_train_on_cuda_says_why_gsplat_cannot_run(monkeypatch, capsys, tmp_path, backend_args, message):
    from cghair_format.cli import main

    _gsplat_import_fails(monkeypatch, RuntimeError("CUDA driver too old"))
    code = main(["train", str(tmp_path), "--strands", "s.npz", "-o", str(tmp_path / "x.cgh"), "--device", "cuda",
                 *backend_args])
    assert code == 2 and message in capsys.readouterr().err  # the empty dataset folder stops the second


_LOADED = object()  # stands for loaded CUDA kernels


def _fake_gsplat(monkeypatch, rasterization=None, kernels=_LOADED):
    """Stand-in ``gsplat`` modules in sys.modules (the real one needs CUDA); for the adapter's plumbing only."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    pkg, cuda, backend = (types.ModuleType(n) for n in ("gsplat", "gsplat.cuda", "gsplat.cuda._backend"))
    pkg.rasterization = rasterization
    backend._C = kernels
    for name, mod in (("gsplat", pkg), ("gsplat.cuda", cuda), ("gsplat.cuda._backend", backend)):
        monkeypatch.setitem(sys.modules, name, mod)


def test_gsplat_without_nvcc(monkeypatch):
    _fake_gsplat(monkeypatch, kernels=None)  # what gsplat leaves when it finds no CUDA toolkit
    with pytest.raises(BackendError, match=r"no CUDA toolkit .* install the CUDA toolkit \(nvcc\)"):
        backends.render_gsplat(*random_scene(3, 0), camera())


# --- the gsplat adapter's conversions (CPU) ------------------------------------------------------------------


def test_gsplat_camera_projects_like_ours():
    cam = Camera.orbit((0.1, -0.2, 0.3), 2.5, 70.0, 25.0, 40, 30, fov_y_deg=50.0)
    pts = np.random.default_rng(0).uniform(-0.5, 0.5, (20, 3))
    viewmat, k = backends.gsplat_camera(cam, torch.zeros(1, dtype=torch.float64))
    assert viewmat.shape == (1, 4, 4) and k.shape == (1, 3, 3)
    cam_pts = torch.as_tensor(pts) @ viewmat[0, :3, :3].T + viewmat[0, :3, 3]
    pix = cam_pts @ k[0].T
    uv, z = cam.project(pts)
    np.testing.assert_allclose((pix[:, :2] / pix[:, 2:]).numpy(), uv, rtol=1e-12)
    np.testing.assert_allclose(cam_pts[:, 2].numpy(), z, rtol=1e-12)


def _gsplat_by_reference(calls):
    """gsplat.rasterization's documented contract (RGB+D, colours given, no background) computed by the
    reference splatter, so the adapter's conversions can be checked without CUDA."""

    def rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, **kw):
        calls.append(kw)
        for t in (means, quats, scales, opacities, colors, viewmats, Ks):
            assert t.dtype == torch.float32, "gsplat's kernels take float32 only"
        w2c = viewmats[0].detach().double().numpy()
        k = Ks[0].detach().double().numpy()
        cam = Camera(width, height, k[0, 0], k[1, 1], k[0, 2], k[1, 2], w2c)
        sh0 = ((colors - 0.5) / SH_C0)[:, None, :]  # band 0 alone renders exactly these colours
        out = splatter.render(means, quats, scales, opacities, sh0, cam)
        return torch.cat([out.rgb, out.depth[..., None]], -1)[None], out.alpha[None, ..., None], {}

    return rasterization


def test_gsplat_adapter_conversions(monkeypatch):
    """float64 inputs reach gsplat as float32 and come back as float64, gradients included; the images
    agree with the reference in float64 to float32's rounding."""
    calls = []
    _fake_gsplat(monkeypatch, _gsplat_by_reference(calls))
    scene = [t.double().requires_grad_() for t in random_scene(40, 1)]
    cam, bg = camera(24), (0.2, 0.1, 0.3)
    want = splatter.render(*scene, cam, bg)
    got = backends.render("gsplat", *scene, cam, bg)
    assert calls == [{"near_plane": splatter.NEAR_PLANE, "eps2d": splatter.DILATION, "sh_degree": None,
                      "packed": False, "rasterize_mode": "classic", "render_mode": "RGB+D"}]
    assert float(want.alpha.detach().max()) > 0.5  # the scene is visible
    for a, b in ((got.rgb, want.rgb), (got.alpha, want.alpha), (got.depth, want.depth)):
        assert a.dtype == torch.float64
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)  # float32 rounding of values near 1
    grads_got = torch.autograd.grad((got.rgb.sum() + got.alpha.sum()), scene)
    grads_want = torch.autograd.grad((want.rgb.sum() + want.alpha.sum()), scene)
    for a, b in zip(grads_got, grads_want, strict=True):
        assert a.dtype == torch.float64
        # float32 sums over the image's pixels: relative to the gradient's largest entry
        torch.testing.assert_close(a, b, rtol=1e-3, atol=1e-4 * float(b.abs().max()))


def test_gsplat_adapter_caps_opacity_and_passes_its_gradient_through(monkeypatch):
    seen = []
    _fake_gsplat(monkeypatch, lambda *a, **kw: seen.append(a[3]) or _gsplat_by_reference([])(*a, **kw))
    means, quats, scales, _, sh = random_scene(5, 2)
    opac = torch.tensor([0.999, 0.995, 0.99, 0.5, 0.2], requires_grad=True)
    out = backends.render_gsplat(means, quats, scales, opac, sh, camera(16))
    assert float(seen[0].detach().max()) == pytest.approx(splatter.ALPHA_MAX)  # gsplat's own cap is 0.999
    grad, = torch.autograd.grad(out.alpha.sum(), opac)
    # above the cap each Gaussian gets the gradient it would have at the cap (a hard clamp gives 0)
    at_cap = opac.detach().clamp_max(splatter.ALPHA_MAX).requires_grad_()
    want, = torch.autograd.grad(backends.render_gsplat(means, quats, scales, at_cap, sh, camera(16)).alpha.sum(),
                                at_cap)
    assert (grad[:2] > 0).all()
    torch.testing.assert_close(grad, want)


# --- gsplat against the reference (CUDA) -----------------------------------------------------------------------


def _psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    return -10 * math.log10(float(((a - b) ** 2).mean()) + 1e-20)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA is absent (where it is present, a missing or "
                    "broken gsplat fails this test)")
@pytest.mark.parametrize("scene_name", ["random", "hair"])
def test_gsplat_matches_reference(scene_name, strands):
    dev = torch.device("cuda")
    scene = random_scene(300, 3) if scene_name == "random" else hair_scene(strands)
    for az in (0.0, 120.0, 250.0):
        cam = camera(64, az)
        ref_in = [t.to(dev).requires_grad_() for t in scene]
        gs_in = [t.to(dev).requires_grad_() for t in scene]
        want = splatter.render(*ref_in, cam, (0.1, 0.2, 0.3))
        got = backends.render("gsplat", *gs_in, cam, (0.1, 0.2, 0.3))
        assert float(want.alpha.detach().max()) > 0.5
        # the contract's images agree to 40 dB; early termination at T < 1e-4 changes a pixel by at most 1e-4
        assert _psnr(got.rgb, want.rgb) >= 40 and _psnr(got.alpha, want.alpha) >= 40
        weights = torch.rand_like(want.rgb)
        g_ref = torch.autograd.grad((want.rgb * weights).sum() + want.alpha.sum(), ref_in)
        g_gs = torch.autograd.grad((got.rgb * weights).sum() + got.alpha.sum(), gs_in)
        for name, a, b in zip(("means", "quats", "scales", "opacities", "sh"), g_gs, g_ref, strict=True):
            # float32 atomics accumulate in a different order, fast-math exp, and the pairs that early
            # termination drops: a few per cent of the gradient's norm, never its direction
            rel = float((a - b).norm() / b.norm().clamp_min(1e-12))
            assert rel < 0.05, f"{name}: relative gradient error {rel:.3g}"
