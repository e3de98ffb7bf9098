"""Rasterizer backends behind one interface: the reference torch splatter, the compiled CPU
rasterizer (``native``) and gsplat on CUDA.

Every backend takes the reference's arguments and returns its :class:`RenderOutput`, and every
one is held to the reference's image contract (:mod:`training.splatter`): EWA projection with a
0.3 px^2 dilation, alpha = min(0.99, o exp(-q/2)), contributions under 1/255 skipped, near plane
0.01, front-to-back compositing; early termination at T < 1e-4 is allowed. ``reference`` is the
source of truth; the others are tested against it (tests/training/test_backends.py).

gsplat (``pip install 'cghair[cuda]'``) differs from the contract in three documented places, all
handled here. Its alpha cap is 0.999, so opacities are clamped to 0.99 before the call (identical
wherever o <= 0.99; above it alpha differs by at most 0.01 at a Gaussian's core), and the clamp passes
the gradient straight through (``o - (o - min(o, 0.99)).detach()``): a Gaussian above 0.99 keeps the
gradient it would have at 0.99, as the reference's per-pixel cap leaves one wherever o exp(-q/2) < 0.99,
instead of none at all, which would freeze every opaque Gaussian. Its kernels take float32 only, so
inputs are cast to float32 at the call and the outputs back to the inputs' dtype (gradients follow
the casts). Colours are evaluated here from our SH exactly as the reference does (direction camera ->
mean, + 0.5, clamp at 0) and passed as RGB, so no SH convention of gsplat's has to match ours. Its
projection also clamps the screen-space Jacobian to 1.3 x the field of view (as 3DGS does), which
changes only Gaussians centred well outside the image.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

from cghair_format.errors import CghError

from . import splatter
from .config import BACKENDS
from .splatter import ALPHA_MAX, DILATION, NEAR_PLANE, RenderOutput, eval_sh, torch_device

if TYPE_CHECKING:
    from cghair_format.camera import Camera
    from cghair_format.gaussians import Gaussians

NATIVE_BUILD = "python setup.py build_ext --inplace"
GSPLAT_INSTALL = "pip install 'cghair[cuda]'"


class BackendError(CghError, ValueError):
    """A rasterizer backend that cannot run here (not built, not installed, wrong device)."""


def _native_module():
    """``training.native_splat`` with its compiled extension, or a BackendError saying how to build it."""
    try:
        importlib.import_module("training._raster")
        return importlib.import_module("training.native_splat")
    except ImportError as exc:
        raise BackendError(f"the native backend is not built ({exc}); run `{NATIVE_BUILD}` in the "
                           "repository, or use --backend reference") from None


def _gsplat_rasterization():
    """``gsplat.rasterization`` with its CUDA kernels loaded, or a BackendError saying what to install."""
    if not torch.cuda.is_available():
        raise BackendError("the gsplat backend needs a CUDA device and this torch has none (install a CUDA "
                           "build of torch), or use --backend native or reference")
    try:
        gsplat = importlib.import_module("gsplat")
    except ImportError:
        raise BackendError(f"the gsplat backend needs the gsplat package: {GSPLAT_INSTALL} "
                           "(it compiles its CUDA kernels with nvcc on first use)") from None
    except Exception as exc:  # an installed gsplat that breaks on import: a torch or CUDA library mismatch
        raise BackendError(f"gsplat is installed but fails to import ({type(exc).__name__}: {exc}); reinstall "
                           f"it against this torch ({GSPLAT_INSTALL}), or use --backend reference") from None
    try:  # a prebuilt wheel carries the kernels; otherwise gsplat compiles them now, and leaves None without nvcc
        kernels = importlib.import_module("gsplat.cuda._backend")._C
    except Exception as exc:  # a failed nvcc build surfaces as any of several exception types
        raise BackendError(f"gsplat could not compile its CUDA kernels ({type(exc).__name__}: {exc}); install the "
                           "CUDA toolkit (nvcc) matching this torch, or a prebuilt gsplat wheel") from None
    if kernels is None:
        raise BackendError("gsplat found no CUDA toolkit to compile its kernels: install the CUDA toolkit (nvcc) "
                           "matching this torch, or a prebuilt gsplat wheel")
    return gsplat.rasterization


def check_backend(name: str, device: str | torch.device = "cpu") -> str:
    """``name`` if that backend runs on the torch ``device`` here, else a BackendError saying why."""
    if name not in BACKENDS:
        raise BackendError(f"unknown backend {name!r}; choose one of {', '.join(BACKENDS)}")
    dev = device if isinstance(device, torch.device) else torch_device(device)
    if name == "native":
        if dev.type != "cpu":
            raise BackendError(f"the native backend runs on the CPU, not {dev}; use --backend gsplat or reference")
        _native_module()
    elif name == "gsplat":
        if dev.type != "cuda":
            raise BackendError(f"the gsplat backend runs on CUDA, not {dev}; use --device cuda, or --backend "
                               "native or reference on the CPU")
        _gsplat_rasterization()
    return name


def available_backends(device: str | torch.device = "cpu") -> list[str]:
    """The backends that run on ``device`` here, in :data:`BACKENDS` order."""
    out = []
    for name in BACKENDS:
        try:
            out.append(check_backend(name, device))
        except BackendError:
            pass
    return out


def default_backend(device: str | torch.device = "cpu") -> str:
    """``native`` on the CPU when it is built, ``gsplat`` on CUDA when it imports, else ``reference``."""
    dev = device if isinstance(device, torch.device) else torch_device(device)
    preferred = "gsplat" if dev.type == "cuda" else "native"
    return preferred if preferred in available_backends(dev) else "reference"


def resolve_backend(name: str | None, device: str | torch.device = "cpu") -> str:
    """The backend to use: ``name`` checked, or the default for ``device`` when ``name`` is None."""
    return default_backend(device) if name is None else check_backend(name, device)


# --- gsplat ----------------------------------------------------------------------------------------------


def gsplat_camera(camera: Camera, like: Tensor) -> tuple[Tensor, Tensor]:
    """gsplat's ``viewmats [1, 4, 4]`` and ``Ks [1, 3, 3]`` of a camera. Both use OpenCV camera axes (x
    right, y down, z forward) and pixel centres at ``i + 0.5``, so the world-to-camera matrix passes as is."""
    kw = {"dtype": like.dtype, "device": like.device}
    viewmat = torch.as_tensor(np.asarray(camera.world_to_camera, np.float64), **kw)
    k = torch.tensor([[float(camera.fx), 0.0, float(camera.cx)], [0.0, float(camera.fy), float(camera.cy)],
                      [0.0, 0.0, 1.0]], **kw)
    return viewmat[None], k[None]


def gsplat_colours(means: Tensor, sh: Tensor, camera: Camera) -> Tensor:
    """RGB ``[G, 3]`` from our SH as the reference evaluates it (direction camera -> mean, +0.5, clamp at 0)."""
    center = torch.as_tensor(np.asarray(camera.center, np.float64), dtype=means.dtype, device=means.device)
    dirs = means - center
    return eval_sh(sh, dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12))


def capped_opacities(opacities: Tensor) -> Tensor:
    """``min(o, ALPHA_MAX)`` forward, the identity backward: the straight-through cap for gsplat."""
    return opacities - (opacities - torch.clamp_max(opacities, ALPHA_MAX)).detach()


def render_gsplat(means, quats, scales, opacities, sh, camera, background=(0.0, 0.0, 0.0)) -> RenderOutput:
    """The reference's :func:`training.splatter.render` through ``gsplat.rasterization`` (CUDA, float32)."""
    rasterization = _gsplat_rasterization()
    f32 = torch.float32
    viewmats, ks = gsplat_camera(camera, means.to(f32))
    colours, alphas, _ = rasterization(
        means.to(f32), quats.to(f32), scales.to(f32), capped_opacities(opacities).to(f32),
        gsplat_colours(means, sh, camera).to(f32), viewmats, ks, int(camera.width), int(camera.height),
        near_plane=NEAR_PLANE, eps2d=DILATION, sh_degree=None, packed=False, rasterize_mode="classic",
        render_mode="RGB+D")
    colours, alpha = colours[0].to(means.dtype), alphas[0, ..., 0].to(means.dtype)
    bg = torch.as_tensor(background, dtype=means.dtype, device=means.device).reshape(3)
    rgb = colours[..., :3] + (1.0 - alpha[..., None]) * bg
    return RenderOutput(rgb, alpha, colours[..., 3])


# --- one entry point ---------------------------------------------------------------------------------------


def _all_sh(render_fn):
    """``render_fn`` taking, as the native splatter does, SH or a function of Gaussian indices giving
    them (:meth:`training.model.HairModel.sh_source`): here asked for all of them."""
    def render_any(means, quats, scales, opacities, sh, camera, background=(0.0, 0.0, 0.0)) -> RenderOutput:
        return render_fn(means, quats, scales, opacities, sh if isinstance(sh, Tensor) else sh(None), camera,
                         background)
    return render_any


def renderer(backend: str):
    """The ``render(means, quats, scales, opacities, sh, camera, background)`` function of a backend;
    ``sh`` is ``[G, C, 3]`` or a function from Gaussian indices (None: all) to their SH, which the
    native backend asks only for the Gaussians that contribute."""
    if backend == "reference":
        return _all_sh(splatter.render)
    if backend == "native":
        return _native_module().render
    if backend == "gsplat":
        return _all_sh(render_gsplat)
    raise BackendError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")


def render(backend: str, means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, sh: Tensor,
           camera: Camera, background: tuple[float, float, float] | Tensor = (0.0, 0.0, 0.0)) -> RenderOutput:
    """Render one camera with ``backend``; the arguments and outputs of :func:`training.splatter.render`."""
    return renderer(backend)(means, quats, scales, opacities, sh, camera, background)


def render_gaussians(g: Gaussians, camera: Camera, background=(0.0, 0.0, 0.0), device: str | torch.device = "cpu",
                     backend: str = "reference") -> dict[str, np.ndarray]:
    """:func:`training.splatter.render_gaussians` with a choice of backend: numpy ``rgb``, ``alpha``, ``depth``."""
    return splatter.render_gaussians(g, camera, background, device, renderer(backend))
