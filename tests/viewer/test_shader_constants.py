"""Constants defined once in Python and injected into the GLSL, and the per-driver work groups."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

from viewer import shader_constants as sc
from viewer.pipeline import SHADER_DIR, image_units, prepared
from viewer.shader_constants import WORKGROUPS, glsl_defines, workgroups_for


@pytest.mark.parametrize("vendor, renderer, profile", [
    ("Mesa/X.org", "llvmpipe (LLVM 15.0.6, 256 bits)", "llvmpipe"),
    ("Mesa", "softpipe", "llvmpipe"),
    ("NVIDIA Corporation", "NVIDIA H100 80GB HBM3/PCIe/SSE2", "NVIDIA"),
    ("AMD", "AMD Radeon RX 7900 XTX (radeonsi, navi31, LLVM 17.0.6, DRM 3.54)", "AMD"),
    ("ATI Technologies Inc.", "AMD Radeon Pro W6800", "AMD"),
    ("Intel", "Mesa Intel(R) UHD Graphics 630 (CFL GT2)", "gpu"),
    (None, None, "gpu"),
])
def test_workgroups_by_driver(vendor, renderer, profile):
    assert workgroups_for(vendor, renderer).profile == profile


def test_gpu_work_groups_fill_warps_of_32():
    for wg in WORKGROUPS.values():
        assert wg.blend[0] == sc.TILE and sc.TILE % wg.blend[1] == 0
        if wg.profile != "llvmpipe":  # llvmpipe: few invocations with a 16-pixel column each
            assert (wg.blend[0] * wg.blend[1]) % 32 == 0
    for size in (sc.LOCAL_SIZE, sc.LATENT_LOCAL_SIZE, sc.RADIX_THREADS, sc.RADIX_SCAN_THREADS):
        assert size % 32 == 0
    record = WORKGROUPS["NVIDIA"].record()
    assert record["blend"] == [16, 16] and record["blend_rows"] == 1 and record["items"] == sc.LOCAL_SIZE


def test_defines_follow_the_python_constants():
    lines = glsl_defines(WORKGROUPS["llvmpipe"]).splitlines()
    assert f"#define TILE {sc.TILE}" in lines and f"#define RUN {sc.RUN}" in lines
    assert "#define TEXEL_ROW_SHIFT 12" in lines and 1 << 12 == sc.TEXELS_PER_ROW
    assert "#define BLEND_GROUP_Y 1" in lines and f"#define BLEND_ROWS {sc.TILE}" in lines


def test_no_shader_restates_a_shared_constant():
    """TILE, the run length, the data images' row shift and the work-group sizes come from the loader."""
    for path in SHADER_DIR.glob("*.glsl"):
        text = path.read_text()
        assert "const uint TILE" not in text and "ROW_SHIFT = " not in text, path.name
        for size in re.findall(r"local_size_[xyz]\s*=\s*(\w+)", text):
            assert not size.isdigit(), f"{path.name}: local size {size}"


def test_prepared_puts_defines_after_the_version_line():
    src = "#version 430\n// body\nvoid main() {}\n"
    assert prepared(src, "#define A 1\n") == "#version 430\n#define A 1\n// body\nvoid main() {}\n"
    assert prepared(src, "", version="330 core").startswith("#version 330 core\n// body")


def test_image_units_are_read_from_the_declarations():
    src = ("layout(rgba32f, binding = 1) uniform writeonly image2D u_records;\n"
           "layout(r32ui, binding = 2) uniform writeonly uimage2D u_entries;\nuniform sampler2D u_sh;\n")
    assert image_units(src) == {"u_records": 1, "u_entries": 2}


@pytest.mark.gl
def test_gpu_blend_layout_draws_the_same_pixels(gl_ctx):
    """The NVIDIA/AMD tile blend (256 invocations, a pixel each) compiled and run on llvmpipe gives
    llvmpipe's own layout's image bit for bit: rows are numbered within the tile either way."""
    from cghair_format.camera import Camera
    from viewer.camera_control import OrbitController
    from viewer.pipeline import Programs
    from viewer.renderer import Renderer
    from viewer.synthetic import synthetic_asset

    asset = synthetic_asset(120, points=11, seed=5)
    images = []
    for profile in ("llvmpipe", "NVIDIA"):
        programs = Programs(gl_ctx, workgroups=WORKGROUPS[profile])
        renderer = Renderer.from_asset(gl_ctx, asset, rasterizer="compute", programs=programs)
        ctl = OrbitController.framing(*renderer.bounds, asset.up_axis)
        images.append(renderer.render(Camera.orbit(ctl.target, ctl.distance, 40.0, 10.0, 75, 53, asset.up_axis)))
        renderer.release()
    assert images[0][..., 3].max() > 0.5
    np.testing.assert_array_equal(images[0], images[1])


def test_no_viewer_function_over_80_lines():
    for path in Path(sc.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                assert node.end_lineno - node.lineno < 80, f"{path.name}: {node.name}"
