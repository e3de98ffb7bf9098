"""Fixtures of the viewer tests: one headless EGL context per session, checked for GL errors after
every test that uses it, and small in-memory assets."""

from __future__ import annotations

import os

import pytest

pytest.importorskip("moderngl", reason="the viewer tests need moderngl (pip install 'cghair[viewer]')")


@pytest.fixture(scope="session")
def _session_ctx():
    from viewer.context import GLContextError, create_headless_context

    try:
        ctx = create_headless_context()
    except GLContextError as exc:
        if os.environ.get("CI"):  # CI promises Mesa's EGL + llvmpipe: a missing context is a failure
            pytest.fail(f"CI is set but no headless OpenGL 4.3 context could be created: {exc}")
        pytest.skip(f"no headless OpenGL 4.3 context on this machine: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture
def gl_ctx(_session_ctx):
    """The headless context, made current; the test fails if it leaves an OpenGL error behind."""
    _session_ctx.__enter__()  # a CLI run in between may have made its own context current
    assert _session_ctx.error == "GL_NO_ERROR"  # also clears a stale error flag
    yield _session_ctx
    assert _session_ctx.error == "GL_NO_ERROR"
