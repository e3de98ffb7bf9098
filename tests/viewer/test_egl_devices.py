"""Choosing the EGL device of a headless context: the order on fake device lists (this machine has
llvmpipe only), the real enumeration here, and the hint for a GPU that OpenGL cannot reach."""

from __future__ import annotations

import pytest

from viewer import egl_devices
from viewer.egl_devices import EglDevice, device_order, graphics_hint

SOFTWARE = "EGL_MESA_device_software EGL_EXT_device_drm_render_node"
NVIDIA = "EGL_NV_device_cuda EGL_EXT_device_drm EGL_EXT_device_query_name"
MESA_GPU = "EGL_EXT_device_drm EGL_EXT_device_drm_render_node"


def test_device_kinds():
    assert EglDevice(0, SOFTWARE).kind == "software"
    assert EglDevice(0, NVIDIA).kind == "nvidia"
    assert EglDevice(0, "EGL_EXT_device_drm", vendor="NVIDIA").kind == "nvidia"  # named, without the CUDA extension
    assert EglDevice(0, MESA_GPU, drm_file="/dev/dri/card1").kind == "gpu"
    assert EglDevice(0, "").kind == "gpu"  # a device that says nothing is taken for hardware


@pytest.mark.parametrize("kinds, order", [
    (["software", "nvidia"], [1, 0]),  # llvmpipe listed first (Mesa's vendor library ahead): NVIDIA still wins
    (["nvidia", "software"], [0, 1]),
    (["software", "gpu", "nvidia", "nvidia"], [2, 3, 1, 0]),  # NVIDIA GPUs in EGL's order, then others
    (["software"], [0]),
    ([], []),
])
def test_nvidia_first_then_other_gpus_then_software(kinds, order):
    ext = {"software": SOFTWARE, "nvidia": NVIDIA, "gpu": MESA_GPU}
    assert device_order([EglDevice(i, ext[k]) for i, k in enumerate(kinds)]) == order


def test_context_asks_for_the_preferred_device(monkeypatch):
    import moderngl

    from viewer.context import create_headless_context

    asked = []

    def fake(require, **kwargs):
        asked.append(kwargs.get("device_index"))
        if kwargs.get("device_index") == 1:
            return type("Ctx", (), {"extra": None})()
        raise RuntimeError("no such device")

    monkeypatch.setattr("viewer.context.egl_devices", lambda: [EglDevice(0, SOFTWARE), EglDevice(1, NVIDIA)])
    monkeypatch.delenv("GLCONTEXT_DEVICE_INDEX", raising=False)
    monkeypatch.setattr(moderngl, "create_standalone_context", fake)
    ctx = create_headless_context()
    assert asked == [1] and ctx.extra["egl_device"].kind == "nvidia"
    asked.clear()
    monkeypatch.setenv("GLCONTEXT_DEVICE_INDEX", "1")  # glcontext obeys it whatever we ask: ask for it
    monkeypatch.setattr("viewer.context.egl_devices", lambda: [EglDevice(0, NVIDIA), EglDevice(1, NVIDIA)])
    assert create_headless_context().extra["egl_device"].index == 1 and asked == [1]


@pytest.mark.gl
def test_real_enumeration_and_context(gl_ctx):
    from viewer.context import gl_info

    devices = egl_devices.egl_devices()
    assert devices and all(d.index == i for i, d in enumerate(devices))
    info = gl_info(gl_ctx)
    assert info["renderer"] == gl_ctx.info["GL_RENDERER"] and info["vendor"] and info["version"]
    device = info["egl_device"]
    assert device is not None and device["index"] == device_order(devices)[0]
    if "llvmpipe" in info["renderer"]:
        assert device["kind"] == "software"


def test_graphics_hint(monkeypatch):
    monkeypatch.setenv("NVIDIA_DRIVER_CAPABILITIES", "compute,utility")
    hint = graphics_hint("llvmpipe (LLVM 15.0.6, 256 bits)", gpu_present=True)
    assert "\n" not in hint and "libEGL_nvidia" in hint and "NVIDIA_DRIVER_CAPABILITIES=compute,utility" in hint
    assert "NVIDIA_DRIVER_CAPABILITIES=all" in hint
    assert graphics_hint("NVIDIA H100 80GB HBM3/PCIe/SSE2", gpu_present=True) is None
    assert graphics_hint("llvmpipe", gpu_present=False) is None
    monkeypatch.setattr(egl_devices, "NVIDIA_PRESENT", ("/nonexistent/nvidia",))
    assert graphics_hint("llvmpipe") is None  # no NVIDIA driver on this machine
