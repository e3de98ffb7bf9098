"""Shader loading, binding by name and compute dispatch shared by the decode, sort and render stages.

Shaders are ``.glsl`` files shipped in ``viewer/shaders``; a line ``#include "NAME"`` is replaced
by that file's text (GLSL has no includes), and the constants of :mod:`viewer.shader_constants`
are ``#define``d after the ``#version`` line. Programs are cached per context. Storage buffers,
images and samplers are bound by the names the shaders declare, never by position: a storage
block's binding point is read from the compiled program, an image's unit from its declaration.
"""

from __future__ import annotations

import math
import re
from functools import cache
from pathlib import Path
from typing import Any

from .context import GLError
from .shader_constants import LOCAL_SIZE, TEXELS_PER_ROW, Workgroups, glsl_defines, workgroups_for

MAX_GROUPS = 65535  # guaranteed per-axis work-group count limit
SHADER_DIR = Path(__file__).resolve().parent / "shaders"
_INCLUDE = re.compile(r'^#include "([\w.]+)"\s*$', re.MULTILINE)


@cache
def shader_source(name: str) -> str:
    """The text of ``viewer/shaders/NAME`` with its ``#include`` lines expanded."""
    text = (SHADER_DIR / name).read_text(encoding="utf-8")
    return _INCLUDE.sub(lambda m: shader_source(m.group(1)), text)


_VERSION = re.compile(r"^#version .*$", re.MULTILINE)
# an image uniform's declaration: its layout qualifiers and its name
_IMAGE = re.compile(r"layout\s*\(([^)]*)\)\s*uniform\s+(?:\w+\s+)*?\w*image\w+\s+(\w+)\s*;")
_BINDING = re.compile(r"\bbinding\s*=\s*(\d+)")


def prepared(source: str, defines: str, version: str | None = None) -> str:
    """``source`` with ``defines`` after its ``#version`` line, which ``version`` replaces if given."""
    line = _VERSION.search(source)
    if line is None:
        raise GLError("a shader must start with a #version line")
    head = line.group(0) if version is None else f"#version {version}"
    return f"{source[:line.start()]}{head}\n{defines}{source[line.end() + 1:]}"


def image_units(source: str) -> dict[str, int]:
    """The image unit of each image uniform of ``source``, from its ``layout(binding = N)`` (moderngl
    reads some image types' units back as 0, so they are taken from the declarations)."""
    units = {}
    for m in _IMAGE.finditer(source):
        binding = _BINDING.search(m.group(1))
        if binding:
            units[m.group(2)] = int(binding.group(1))
    return units


def driver_workgroups(ctx: Any) -> Workgroups:
    """The work-group shapes of this context's driver (:func:`viewer.shader_constants.workgroups_for`)."""
    return workgroups_for(ctx.info.get("GL_VENDOR"), ctx.info.get("GL_RENDERER"))


class Programs:
    """Compiled programs of one context, built on first use.

    ``version`` overrides the render shaders' ``#version`` line: the compute-free fallback
    compiles the shaders that need nothing from GLSL 4.30 as ``330 core``. ``workgroups``: the
    driver's table entry by default; tests compile another driver's shapes on llvmpipe.
    """

    def __init__(self, ctx: Any, version: str | None = None, workgroups: Workgroups | None = None):
        self.ctx = ctx
        self.version = version
        self.workgroups = workgroups or driver_workgroups(ctx)
        self._defines = glsl_defines(self.workgroups)
        self._cache: dict[tuple[str, ...], Any] = {}

    def compute(self, name: str) -> Any:
        key = (name,)
        if key not in self._cache:
            source = prepared(shader_source(f"{name}.comp.glsl"), self._defines)
            try:
                program = self.ctx.compute_shader(source)
            except Exception as exc:
                raise GLError(f"compute shader {name} failed to compile: {exc}") from exc
            program.extra = {"image_units": image_units(source)}
            self._cache[key] = program
        return self._cache[key]

    def render(self, vertex: str, fragment: str) -> Any:
        key = (vertex, fragment)
        if key not in self._cache:
            try:
                self._cache[key] = self.ctx.program(
                    vertex_shader=prepared(shader_source(f"{vertex}.vert.glsl"), self._defines, self.version),
                    fragment_shader=prepared(shader_source(f"{fragment}.frag.glsl"), self._defines, self.version))
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


def bind(program: Any, **buffers: Any) -> None:
    """Bind storage buffers to the blocks of ``program`` named by the keywords (the GLSL block
    names, e.g. ``Keys=``); blocks the compiler optimised away are skipped."""
    for name, buf in buffers.items():
        if name in program:
            buf.bind_to_storage_buffer(program[name].binding)


def bind_images(program: Any, read: bool = False, **images: Any) -> None:
    """Bind textures as the write-only images (read-write where ``read``) of the compute ``program``
    named by the keywords (its image uniforms, on the units their declarations give)."""
    units = program.extra["image_units"]
    for name, image in images.items():
        if name not in units:
            raise GLError(f"the compute shader declares no image {name} (it has {sorted(units)})")
        image.bind_to_image(units[name], read=read, write=True)


def use_textures(program: Any, **textures: Any) -> None:
    """Bind textures to the samplers of ``program`` named by the keywords, on units 0, 1, ... in
    keyword order, and point each sampler at its unit."""
    for unit, (name, texture) in enumerate(textures.items()):
        texture.use(unit)
        if name in program:
            program[name].value = unit
