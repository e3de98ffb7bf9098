"""The one place that creates OpenGL contexts: a glfw window, or a headless EGL context.

Both ask for OpenGL 4.3 core (compute shaders, storage buffers) and settle for 3.3 core, which
the compute-free fallback renderer needs. Mesa's llvmpipe provides 4.5 without a GPU or a
display, which is how tests and ``cgh render`` run on servers and in CI.
"""

from __future__ import annotations

import os
import warnings
from typing import Any

from cghair_format.errors import CghError, require

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
    """A standalone OpenGL 4.3 context without a window (EGL, e.g. Mesa llvmpipe on a CPU)."""
    moderngl = require("moderngl", "viewer", "headless rendering")
    errors = []
    for version in (GL_REQUIRE, GL_FALLBACK):
        for kwargs in ({"backend": "egl"}, {}):
            try:
                return moderngl.create_standalone_context(require=version, **kwargs)
            except Exception as exc:  # moderngl raises plain Exception subclasses from its loaders
                errors.append(f"GL {version / 100:.1f} {kwargs.get('backend', 'default')}: {exc}")
    raise GLContextError(
        "could not create a headless OpenGL 4.3 context (" + "; ".join(errors) + "). Install Mesa's "
        "EGL and software renderer (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri) or a GPU driver.")


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
