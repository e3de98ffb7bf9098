"""Shader loading and compute dispatch shared by the decode, sort and render stages.

Shaders are ``.glsl`` files shipped in ``viewer/shaders``; a line ``#include "NAME"`` is replaced
by that file's text (GLSL has no includes). Programs are cached per context.
"""

from __future__ import annotations

import math
import re
from functools import cache
from pathlib import Path
from typing import Any

from .context import GLError

LOCAL_SIZE = 256  # work-group size of the one-invocation-per-item compute shaders
TEXELS_PER_ROW = 4096  # width of the data images (tile_texel.glsl)
MAX_GROUPS = 65535  # guaranteed per-axis work-group count limit
SHADER_DIR = Path(__file__).resolve().parent / "shaders"
_INCLUDE = re.compile(r'^#include "([\w.]+)"\s*$', re.MULTILINE)


@cache
def shader_source(name: str) -> str:
    """The text of ``viewer/shaders/NAME`` with its ``#include`` lines expanded."""
    text = (SHADER_DIR / name).read_text(encoding="utf-8")
    return _INCLUDE.sub(lambda m: shader_source(m.group(1)), text)


def versioned(source: str, version: str | None) -> str:
    """``source`` with its ``#version`` line replaced (``None``: unchanged)."""
    if version is None:
        return source
    return re.sub(r"^#version .*$", f"#version {version}", source, count=1, flags=re.MULTILINE)


class Programs:
    """Compiled programs of one context, built on first use.

    ``version`` overrides the render shaders' ``#version`` line: the compute-free fallback
    compiles the shaders that need nothing from GLSL 4.30 as ``330 core``.
    """

    def __init__(self, ctx: Any, version: str | None = None):
        self.ctx = ctx
        self.version = version
        self._cache: dict[tuple[str, ...], Any] = {}

    def compute(self, name: str) -> Any:
        key = (name,)
        if key not in self._cache:
            try:
                self._cache[key] = self.ctx.compute_shader(shader_source(f"{name}.comp.glsl"))
            except Exception as exc:
                raise GLError(f"compute shader {name} failed to compile: {exc}") from exc
        return self._cache[key]

    def render(self, vertex: str, fragment: str) -> Any:
        key = (vertex, fragment)
        if key not in self._cache:
            try:
                self._cache[key] = self.ctx.program(
                    vertex_shader=versioned(shader_source(f"{vertex}.vert.glsl"), self.version),
                    fragment_shader=versioned(shader_source(f"{fragment}.frag.glsl"), self.version))
            except Exception as exc:
                raise GLError(f"shader program {vertex}/{fragment} failed to compile: {exc}") from exc
        return self._cache[key]


def set_uniforms(program: Any, **values: Any) -> None:
    """Set the uniforms a program uses; names the compiler optimised away are skipped."""
    for name, value in values.items():
        if name in program:
            program[name].value = value


def dispatch(ctx: Any, program: Any, count: int, local_size: int = LOCAL_SIZE) -> None:
    """Run ``program`` over ``count`` items as a 2D grid of work groups (see ``global_index()``)."""
    if count <= 0:
        return
    groups = math.ceil(count / local_size)
    gx = min(groups, MAX_GROUPS)
    gy = math.ceil(groups / gx)
    program.run(gx, gy, 1)
    ctx.memory_barrier()


def max_texture_size(ctx: Any) -> int:
    return int(ctx.info.get("GL_MAX_TEXTURE_SIZE") or 16384)


def data_image(ctx: Any, texels: int, components: int, dtype: str) -> Any:
    """A ``TEXELS_PER_ROW``-wide 2D texture holding at least ``texels`` texels, fetched exactly.
    Shaders read per-item data from such images rather than storage buffers where it is fetched
    often: llvmpipe fetches texels as vectors but loads storage one invocation at a time."""
    tex = ctx.texture((TEXELS_PER_ROW, max(1, math.ceil(texels / TEXELS_PER_ROW))), components, dtype=dtype)
    tex.filter = (ctx.NEAREST, ctx.NEAREST)
    return tex


def bind(*buffers: Any) -> None:
    """Bind storage buffers to bindings 0, 1, ... in order (``None`` leaves a binding alone)."""
    for binding, buf in enumerate(buffers):
        if buf is not None:
            buf.bind_to_storage_buffer(binding)
