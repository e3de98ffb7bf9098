"""Context creation: the EGL path works here; failures become CghErrors with actionable messages."""

from __future__ import annotations

import sys

import pytest

from cghair_format.errors import MissingDependencyError
from viewer.context import GLContextError, GLError, check_gl, create_headless_context, park_framebuffer

pytestmark = pytest.mark.gl


def test_headless_context_has_compute(gl_ctx):
    assert gl_ctx.version_code >= 430
    check_gl(gl_ctx, "nothing")
    park_framebuffer(gl_ctx)
    park_framebuffer(gl_ctx)  # idempotent: one parking framebuffer per context
    assert "cghair_park_fbo" in gl_ctx.extra


def test_gl_errors_are_reported():
    class FakeContext:
        error = "GL_INVALID_OPERATION"

    with pytest.raises(GLError, match="GL_INVALID_OPERATION during draw"):
        check_gl(FakeContext(), "draw")


def test_no_driver_gives_an_install_hint(monkeypatch):
    import moderngl

    def fail(**kwargs):
        raise RuntimeError("libEGL.so: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    with pytest.raises(GLContextError, match="libegl1 libgl1-mesa-dri"):
        create_headless_context()


def test_missing_moderngl_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "moderngl", None)
    with pytest.raises(MissingDependencyError, match=r"cghair\[viewer\]"):
        create_headless_context()


def test_render_without_gl_is_a_clean_cli_error(monkeypatch, tmp_path, capsys):
    import moderngl

    import cghair_format
    from cghair_format.cli import main
    from cghair_format.examples import example_asset

    path = tmp_path / "a.cgh"
    cghair_format.write(example_asset(), path)
    monkeypatch.setattr(moderngl, "create_standalone_context",
                        lambda **kw: (_ for _ in ()).throw(RuntimeError("no EGL display")))
    assert main(["render", str(path), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "could not create a headless OpenGL 4.3 context" in err and "Traceback" not in err


def test_context_falls_back_to_gl33(monkeypatch):
    import moderngl

    real = moderngl.create_standalone_context
    asked = []

    def only_33(require, **kwargs):
        asked.append(require)
        if require > 330:
            raise RuntimeError("GL 4.3 not supported")
        return real(require=require, **kwargs)

    monkeypatch.setattr(moderngl, "create_standalone_context", only_33)
    ctx = create_headless_context()
    assert asked[-1] == 330 and 430 in asked
    ctx.release()


def test_renderer_choice_follows_the_gl_version(gl_ctx, monkeypatch):
    from cghair_format.examples import example_asset
    from viewer.fallback import FallbackRenderer
    from viewer.renderer import Renderer, create_renderer

    asset = example_asset(strands=10, points=5)
    gpu = create_renderer(gl_ctx, asset)
    assert type(gpu) is Renderer
    gpu.release()
    monkeypatch.setattr(gl_ctx, "version_code", 330)
    cpu = create_renderer(gl_ctx, asset)
    assert isinstance(cpu, FallbackRenderer) and cpu.sort_mode == "cpu"
    cpu.release()
