"""One frame of the viewer, written once: what every renderer shares, and the stage clock.

A renderer (:class:`viewer.renderer.Renderer` with compute shaders, or
:class:`viewer.fallback.FallbackRenderer` on OpenGL 3.3) implements :meth:`SplatRenderer.frame`,
which splats what a camera sees into the accumulation target, stage by stage. ``cgh render``
(:meth:`SplatRenderer.render`), the window (:mod:`viewer.app`) and the benchmark
(:mod:`viewer.bench`, which times each stage through ``stage``) all draw through it; then
:meth:`SplatRenderer.composite` adds the background and the overlays.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from cghair_format.camera import Camera

from .context import check_gl, park_framebuffer
from .pipeline import Programs, set_uniforms
from .rasterizer import Target

MAX_TARGET_SIZES = 2  # render target sizes kept allocated at once
STAGES = ("preprocess", "sort", "gather", "draw")  # the stages of a frame, in order
CARD_STAGES = ("upload", "decode")  # an animated frame's stages before them (Renderer.move_cards)

T = TypeVar("T")
Stage = Callable[[str, Callable[[], T]], T]  # runs one named stage of a frame and returns its result


def run_stage(name: str, fn: Callable[[], T]) -> T:
    """The default ``stage``: run it."""
    return fn()


@dataclass
class ViewSettings:
    """What the viewer's toggles change."""

    sh_degree: int | None = None  # None: the file's degree
    splat_scale: float = 1.0
    color_by_group: bool = False
    show_cards: bool = False
    show_strands: bool = False
    hide_splats: bool = False
    turn_sh: bool = True  # hair that moves: turn each Gaussian's SH with its segment (where decoded)
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)


class SplatRenderer(ABC):
    """Draws Gaussians from any camera into float targets: the frame (by the subclass), then the
    background and overlays, and reading the image back."""

    supports_budget = False  # whether ``budget`` (level of detail) is honoured
    supports_animation = False  # whether the cards can move (``move_cards``)

    def __init__(self, ctx: Any, programs: Programs):
        self.ctx = ctx
        self.programs = programs
        self.budget: int | None = None
        self._targets: dict[tuple[int, int], tuple[Target, Target]] = {}
        self._composite_vao = None

    @property
    @abstractmethod
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space box of the Gaussians (for framing)."""

    @property
    @abstractmethod
    def count(self) -> int:
        """Gaussians in the scene."""

    @property
    @abstractmethod
    def drawn(self) -> int:
        """Gaussians the last frame processed."""

    @abstractmethod
    def describe(self) -> str:
        """What the last frame drew, for the window title."""

    @abstractmethod
    def frame(self, camera: Camera, settings: ViewSettings | None = None, stage: Stage = run_stage) -> None:
        """Splat the Gaussians seen by ``camera`` into :meth:`accum` of its size, running each of
        :data:`STAGES` through ``stage``."""

    @abstractmethod
    def overlays(self, camera: Camera, settings: ViewSettings, flip_y: bool) -> None:
        """Draw the card and strand overlays the settings ask for."""

    def accum(self, width: int, height: int) -> Target:
        """The accumulation target of this size (the splats, before the background)."""
        return self._target(width, height)[0]

    def output(self, width: int, height: int) -> Target:
        """The output target of this size (background and overlays added)."""
        return self._target(width, height)[1]

    def composite(self, camera: Camera, settings: ViewSettings, target: Any = None, flip_y: bool = False) -> None:
        """Background behind the splats, then overlays, into ``target`` (default: the output FBO)."""
        fbo = target or self.output(camera.width, camera.height).framebuffer
        fbo.use()
        self.ctx.disable(self.ctx.BLEND)
        prog = self.programs.render("composite", "composite")
        self.accum(camera.width, camera.height).texture.use(0)
        set_uniforms(prog, u_accum=0, u_background=tuple(float(c) for c in settings.background), u_flip_y=flip_y)
        if settings.hide_splats:
            fbo.clear(*settings.background, 0.0)
        else:
            if self._composite_vao is None:
                self._composite_vao = self.ctx.vertex_array(prog, [])
            self._composite_vao.render(mode=self.ctx.TRIANGLES, vertices=3)
        if settings.show_cards or settings.show_strands:
            self.overlays(camera, settings, flip_y)

    def render(self, camera: Camera, settings: ViewSettings | None = None) -> np.ndarray:
        """The image ``[H, W, 4]`` float32 (RGB with background, and alpha) seen by ``camera``."""
        s = settings or ViewSettings()
        if s.hide_splats:
            self.accum(camera.width, camera.height).framebuffer.clear(0.0, 0.0, 0.0, 0.0)
        else:
            self.frame(camera, s)
        self.composite(camera, s)
        out = self.output(camera.width, camera.height).texture
        image = np.frombuffer(out.read(), np.float32).reshape(camera.height, camera.width, 4)
        check_gl(self.ctx, "render")
        return image.copy()

    def _target(self, width: int, height: int) -> tuple[Target, Target]:
        key = (int(width), int(height))
        if key not in self._targets and len(self._targets) >= MAX_TARGET_SIZES:  # e.g. a resized window
            park_framebuffer(self.ctx)
            self._release_targets(self._targets.pop(next(iter(self._targets))))
        if key not in self._targets:
            accum, out = self.ctx.texture(key, 4, dtype="f4"), self.ctx.texture(key, 4, dtype="f4")
            self._targets[key] = (Target(accum, self.ctx.framebuffer([accum])),
                                  Target(out, self.ctx.framebuffer([out])))
        return self._targets[key]

    @staticmethod
    def _release_targets(targets: tuple[Target, Target]) -> None:
        for target in targets:
            target.framebuffer.release()
            target.texture.release()

    def release(self) -> None:
        """Free the targets (subclasses free their own objects, then call this)."""
        if self._targets:
            park_framebuffer(self.ctx)
        for targets in self._targets.values():
            self._release_targets(targets)
        self._targets.clear()
        if self._composite_vao is not None:
            self._composite_vao.release()
            self._composite_vao = None
