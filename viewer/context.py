"""The one place that creates OpenGL contexts: a glfw window, or a headless EGL context (on the
NVIDIA device where there is one, :mod:`viewer.egl_devices`).

Both ask for OpenGL 4.3 core (compute shaders, storage buffers) and settle for 3.3 core, which
the compute-free fallback renderer needs. Mesa's llvmpipe provides 4.5 without a GPU or a
display, which is how tests and ``cgh render`` run on servers and in CI.
"""

from __future__ import annotations

import os
import warnings
from typing import Any

from cghair_format.errors import CghError, require

from .egl_devices import device_order, egl_devices, forced_index, graphics_hint

GL_REQUIRE = 430  # compute shaders and storage buffers: the GPU pipeline
GL_FALLBACK = 330  # without them: numpy decode, projection and sort (viewer.fallback)


class GLContextError(CghError):
    """No usable OpenGL 4.3 context could be created (no driver, no display, old GL)."""


class GLError(CghError):
    """OpenGL reported an error while the viewer was drawing or computing."""


def check_gl(ctx: Any, where: str) -> None:
    """Raise :class:`GLError` if ``ctx.error`` is not ``GL_NO_ERROR``."""
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise GLError(f"OpenGL error {err} during {where}")


def create_headless_context() -> Any:
    """A standalone OpenGL 4.3 context without a window: on the NVIDIA EGL device where there is
    one, else another GPU, else Mesa's llvmpipe on the CPU (:mod:`viewer.egl_devices`). The EGL
    device used is kept in ``ctx.extra["egl_device"]`` (``None``: the backend's default)."""
    moderngl = require("moderngl", "viewer", "headless rendering")
    devices = egl_devices()
    forced = forced_index()
    order = [forced] if forced is not None else device_order(devices)
    attempts = [({"backend": "egl", "device_index": i}, i) for i in order] + [({"backend": "egl"}, None), ({}, None)]
    errors = []
    for version in (GL_REQUIRE, GL_FALLBACK):
        for kwargs, index in attempts:
            try:
                ctx = moderngl.create_standalone_context(require=version, **kwargs)
            except Exception as exc:  # moderngl raises plain Exception subclasses from its loaders
                where = f"EGL device {index}" if index is not None else kwargs.get("backend", "default")
                errors.append(f"GL {version / 100:.1f} {where}: {exc}")
                continue
            ctx.extra = {"egl_device": next((d for d in devices if d.index == index), None)}
            return ctx
    hint = graphics_hint(None)
    raise GLContextError(
        "could not create a headless OpenGL 4.3 context (" + "; ".join(errors) + "). Install Mesa's "
        "EGL and software renderer (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri) or a GPU driver"
        + (f"; {hint}" if hint else "") + ".")


def gl_info(ctx: Any) -> dict:
    """The driver and device a context runs on (GL_RENDERER, GL_VENDOR, GL_VERSION, the EGL device),
    and a hint where an NVIDIA GPU is present but unused (for ``--verbose`` and benchmark JSON)."""
    renderer = ctx.info.get("GL_RENDERER")
    device = ctx.extra.get("egl_device") if isinstance(ctx.extra, dict) else None
    return {"renderer": renderer, "vendor": ctx.info.get("GL_VENDOR"), "version": ctx.info.get("GL_VERSION"),
            "egl_device": device.record() if device is not None else None, "hint": graphics_hint(renderer)}


def describe_gl(info: dict) -> str:
    """:func:`gl_info` as lines for a terminal."""
    device = info["egl_device"]
    where = f", EGL device {device['index']} ({device['kind']})" if device else ""
    lines = [f"OpenGL: {info['renderer']} | {info['vendor']} | {info['version']}{where}"]
    return "\n".join(lines + ([f"hint: {info['hint']}"] if info["hint"] else []))


def create_window(width: int, height: int, title: str) -> tuple[Any, Any]:
    """A glfw window with an OpenGL 4.3 core context; returns ``(window, moderngl context)``."""
    glfw = require("glfw", "viewer", "the interactive viewer")
    moderngl = require("moderngl", "viewer", "the interactive viewer")
    no_display = not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY")
    with warnings.catch_warnings():  # glfw warns, then returns False: the error below says it better
        warnings.simplefilter("ignore")
        ok = glfw.init()
    if not ok:
        hint = " (no DISPLAY or WAYLAND_DISPLAY is set)" if no_display else ""
        raise GLContextError(f"cannot open a window: glfw failed to initialise{hint}. Without a display, "
                             "use `cgh render FILE.cgh -o out.png` for pictures.")
    window = None
    for version in (GL_REQUIRE, GL_FALLBACK):  # 3.3 where 4.3 is missing (macOS): the numpy path
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, version // 100)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, version % 100 // 10)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            window = glfw.create_window(width, height, title, None, None)
        if window:
            break
    if not window:
        glfw.terminate()
        raise GLContextError("cannot open an OpenGL 3.3 or 4.3 window (the driver may be too old). "
                             "Use `cgh render FILE.cgh -o out.png` for pictures without a window.")
    glfw.make_context_current(window)
    glfw.swap_interval(0)
    return window, moderngl.create_context(require=GL_FALLBACK)


def park_framebuffer(ctx: Any) -> None:
    """Bind a 1x1 framebuffer that lives as long as the context.

    Call before releasing a bound framebuffer: moderngl otherwise re-binds the deleted one after
    creating the next framebuffer, which is a GL_INVALID_OPERATION (a standalone context has no
    default framebuffer to fall back to).
    """
    if not isinstance(ctx.extra, dict):
        ctx.extra = {}
    if "cghair_park_fbo" not in ctx.extra:
        ctx.extra["cghair_park_fbo"] = ctx.framebuffer([ctx.renderbuffer((1, 1))])
    ctx.extra["cghair_park_fbo"].use()
