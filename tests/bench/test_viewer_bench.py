"""Viewer timings at the paper's scale (25,000 strands x 100 Gaussians = 2.5 M, 1920 x 1080): both
rasterizers at full quality and three splat budgets, by stage, with PSNR against full quality and
against the reference splatter (at 480 x 270).

Reports figures (printed and in the benchmark's extra_info); never asserts times. Run with
``make bench`` or ``cgh bench-viewer --synthetic 25000``.
"""

from __future__ import annotations

import pytest

pytest.importorskip("moderngl", reason="the viewer benchmark needs moderngl (pip install 'cghair[viewer]')")

PAPER_STRANDS = 25_000
PAPER_POINTS = 101  # 100 Gaussians per strand


@pytest.mark.bench
@pytest.mark.slow
@pytest.mark.gl
def test_viewer_paper_scale(benchmark):
    from viewer.bench import benchmark as run_benchmark
    from viewer.bench import format_report
    from viewer.context import GLContextError, create_headless_context

    try:
        ctx = create_headless_context()
    except GLContextError as exc:
        pytest.skip(f"no headless OpenGL 4.3 context: {exc}")
    result = benchmark.pedantic(
        lambda: run_benchmark(synthetic=PAPER_STRANDS, points=PAPER_POINTS, width=1920, height=1080,
                              frames=3, ctx=ctx), rounds=1, iterations=1)
    benchmark.extra_info.update({k: v for k, v in result.items() if v is not None})
    print("\n" + format_report(result))
    assert result["gaussians"] == PAPER_STRANDS * (PAPER_POINTS - 1)
    assert {(r["rasterizer"], r["budget"] is None) for r in result["runs"]} == {
        (ras, full) for ras in ("compute", "raster") for full in (True, False)}
    assert ctx.error == "GL_NO_ERROR"
