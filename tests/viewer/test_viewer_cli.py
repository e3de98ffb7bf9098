"""``cgh render``, ``cgh view`` and ``cgh bench-viewer`` from the command line (headless)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

import cghair_format
from cghair_format.camera import Camera
from cghair_format.cli import main
from cghair_format.examples import example_asset
from viewer.render_jobs import RenderJob, nerf_camera, render_job

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def cgh_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("viewer") / "hair.cgh"
    cghair_format.write(example_asset(seed=6, strands=60, points=10, sh_degree=2), path)
    return path


def _run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return rc, out, err


def test_render_png(gl_ctx, cgh_file, tmp_path, capsys):
    out = tmp_path / "hair.png"
    rc, stdout, _ = _run(capsys, "render", cgh_file, "-o", out, "--width", 64, "--height", 48,
                         "--azimuth", 30, "--elevation", 20, "--background", 0.1, 0.1, 0.1)
    assert rc == 0 and "wrote" in stdout
    img = np.asarray(Image.open(out))
    assert img.shape == (48, 64, 3)
    assert img.max() > 60 and (img == 26).all(axis=-1).mean() > 0.3  # hair over a 0.1 grey background


def test_render_of_a_variable_count_file_matches_its_fallback_splats(gl_ctx, tmp_path, capsys):
    """Strands of their own point counts (spec 3): the GPU path (placeholders decoded at opacity 0) and
    the OpenGL 3.3 fallback (decode_gaussians' real segments) draw the same hair."""
    from cghair_format.examples import with_point_counts

    src = tmp_path / "v.cgh"
    cghair_format.write(with_point_counts(example_asset(seed=6, strands=60, points=10, sh_degree=2), seed=2), src)
    images = []
    for raster in ("compute", "raster"):
        out = tmp_path / f"{raster}.png"
        rc, _, _ = _run(capsys, "render", src, "-o", out, "--width", 64, "--height", 48, "--rasterizer", raster)
        assert rc == 0
        images.append(np.asarray(Image.open(out)).astype(np.int64))
    assert images[0].max() > 60 and np.abs(images[0] - images[1]).max() <= 1  # the same image to 8 bits


def test_render_turntable_gif_and_mp4(gl_ctx, cgh_file, tmp_path, capsys):
    gif = tmp_path / "turn.gif"
    rc, _, _ = _run(capsys, "render", cgh_file, "-o", gif, "--width", 40, "--height", 40, "--turntable", 3)
    assert rc == 0
    with Image.open(gif) as im:
        assert im.n_frames == 3
        frames = []
        for i in range(3):
            im.seek(i)
            frames.append(np.asarray(im.convert("RGB")))
    assert not np.array_equal(frames[0], frames[1])
    mp4 = tmp_path / "turn.mp4"
    rc, _, err = _run(capsys, "render", cgh_file, "-o", mp4, "--width", 41, "--height", 40, "--turntable", 2)
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        assert rc == 2 and "imageio-ffmpeg" in err and "cghair[viewer]" in err
    else:
        assert rc == 0 and mp4.stat().st_size > 0


def test_render_from_transforms_json(gl_ctx, cgh_file, tmp_path, capsys):
    asset = cghair_format.read(cgh_file)
    cam = Camera.orbit(asset.cards.spine.reshape(-1, 3).mean(0), 0.5, 70.0, -10.0, 56, 40)
    transforms = tmp_path / "transforms.json"
    transforms.write_text(json.dumps({"camera_angle_x": cam.fov_x, "frames": [
        {"file_path": "a", "transform_matrix": np.eye(4).tolist()},
        {"file_path": "b", "transform_matrix": cam.nerf_matrix().tolist()}]}))
    loaded = nerf_camera(transforms, frame=1, width=56, height=40)
    np.testing.assert_allclose(loaded.world_to_camera, cam.world_to_camera, atol=1e-9)
    out = tmp_path / "nerf.png"
    rc, _, _ = _run(capsys, "render", cgh_file, "-o", out, "--camera", transforms, "--frame", 1,
                    "--width", 56, "--height", 40)
    assert rc == 0
    direct = tmp_path / "direct.png"
    job = RenderJob(width=56, height=40, transforms=str(transforms), frame=1)
    render_job(asset, job, direct, ctx=gl_ctx)
    np.testing.assert_array_equal(np.asarray(Image.open(out)), np.asarray(Image.open(direct)))
    assert np.asarray(Image.open(out)).max() > 40


@pytest.mark.parametrize("args, message", [
    (["-o", "{tmp}/x.bmp"], "unsupported output"),
    (["-o", "{tmp}/x.png", "--turntable", "4"], ".gif or .mp4"),
    (["-o", "{tmp}/x.gif", "--turntable", "-1"], "--turntable must be >= 0"),
    (["-o", "{tmp}/x.png", "--width", "0"], "width must be between"),
    (["-o", "{tmp}/x.png", "--distance", "-2"], "--distance must be a positive"),
    (["-o", "{tmp}/x.png", "--fov", "0"], "--fov must be between"),
    (["-o", "{tmp}/x.gif", "--turntable", "2", "--fps", "0"], "--fps must be positive"),
    (["-o", "{tmp}/nowhere/x.png"], "does not exist"),
    (["-o", "{tmp}/x.png", "--camera", "{tmp}/bad.json"], "no 'frames' list"),
    (["-o", "{tmp}/x.png", "--camera", "{tmp}/one.json", "--frame", "3"], "frame 3 does not exist"),
    (["-o", "{tmp}/x.png", "--camera", "{tmp}/broken.json"], "not valid JSON"),
    (["-o", "{tmp}/x.png", "--camera", "{tmp}/nofov.json"], "neither 'camera_angle_x' nor 'fl_x'"),
    (["-o", "{tmp}/x.png", "--camera", "{tmp}/textfov.json"], "field of view is not a number"),
])
def test_render_errors(gl_ctx, cgh_file, tmp_path, capsys, args, message):
    (tmp_path / "bad.json").write_text("{}")
    (tmp_path / "broken.json").write_text("{frames")
    (tmp_path / "one.json").write_text(json.dumps({"camera_angle_x": 0.7, "frames": [
        {"transform_matrix": np.eye(4).tolist()}]}))
    frames = [{"transform_matrix": np.eye(4).tolist()}]
    (tmp_path / "nofov.json").write_text(json.dumps({"frames": frames}))
    (tmp_path / "textfov.json").write_text(json.dumps({"camera_angle_x": "wide", "frames": frames}))
    rc, _, err = _run(capsys, "render", cgh_file, *[a.format(tmp=tmp_path) for a in args])
    assert rc == 2 and message in err


def test_render_missing_and_bad_files(gl_ctx, tmp_path, capsys):
    rc, _, err = _run(capsys, "render", tmp_path / "absent.cgh", "-o", tmp_path / "x.png")
    assert rc == 2 and "absent.cgh" in err
    junk = tmp_path / "junk.cgh"
    junk.write_bytes(b"not a cgh file at all")
    rc, _, err = _run(capsys, "render", junk, "-o", tmp_path / "x.png")
    assert rc == 2 and "error" in err


def test_view_without_display_suggests_render(cgh_file, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    rc, _, err = _run(capsys, "view", cgh_file)
    assert rc == 2 and "cgh render" in err
    rc, _, err = _run(capsys, "view", cgh_file, "--width", "0")
    assert rc == 2 and "--width must be between" in err


@pytest.mark.parametrize(("flag", "turn_sh"), [((), True), (("--no-turn-sh",), False)])
def test_view_passes_no_turn_sh(cgh_file, capsys, monkeypatch, flag, turn_sh):
    from viewer import app

    calls = []
    monkeypatch.setattr(app, "run_viewer", lambda asset, **kwargs: calls.append(kwargs))
    rc, _, _ = _run(capsys, "view", cgh_file, *flag)
    assert rc == 0 and calls[0]["turn_sh"] is turn_sh


def test_bench_viewer_small(gl_ctx, cgh_file, tmp_path, capsys):
    out = tmp_path / "bench.json"
    rc, stdout, _ = _run(capsys, "bench-viewer", "--synthetic", 200, "--points", 11, "--width", 64,
                         "--height", 48, "--frames", 2, "--budget", 500, "1k", "--reference-size", 48, 36,
                         "--json", out)
    assert rc == 0
    assert "decode+upload" in stdout and "bare instanced quads" in stdout and "reference splatter at 48x36" in stdout
    figures = json.loads(out.read_text())
    # the OpenGL driver and device, and the work-group sizes of this driver's table entry
    assert figures["gl"]["renderer"] == gl_ctx.info["GL_RENDERER"] and figures["gl"]["version"]
    assert figures["workgroups"]["profile"] == "llvmpipe" and figures["workgroups"]["blend"] == [16, 1]
    assert f"OpenGL {figures['gl']['version']}" in stdout and "work groups: llvmpipe (tile blend 16 x 1)" in stdout
    assert figures["gaussians"] == 2000 and figures["strands"] == 200
    for key in ("read_s", "decode_upload_s", "bare_quads_s", "bare_quads_records_s", "sort_gpu_s", "sort_cpu_s",
                "draw_instanced_quads_s", "reference_s"):
        assert figures[key] > 0
    runs = figures["runs"]
    assert figures["compute_over_raster"] == runs[0]["frame_s"] / runs[3]["frame_s"]
    assert "compute / raster frame time at full quality" in stdout
    assert [(r["rasterizer"], r["budget"]) for r in runs] == [
        (ras, b) for ras in ("compute", "raster") for b in (None, 500, 1000)]
    for run in runs:
        assert all(run[k] > 0 for k in ("preprocess_s", "sort_s", "gather_s", "draw_s", "frame_s"))
        assert run["psnr_vs_reference_db"] > (35.0 if run["budget"] is None else 20.0)
        assert (run["psnr_vs_full_db"] is None) == (run["budget"] is None)
        assert run["gaussians_drawn"] == (2000 if run["budget"] is None else run["budget"])
        assert (run["tile_entries"] is not None) == (run["rasterizer"] == "compute")
    rc, stdout, _ = _run(capsys, "bench-viewer", cgh_file, "--width", 32, "--height", 32, "--frames", 1,
                         "--rasterizer", "compute", "--no-reference")
    assert rc == 0 and "hair.cgh" in stdout and "MB" in stdout and "no reference splatter" in stdout
    assert "raster " not in stdout and "bare instanced" not in stdout


def test_render_rasterizers_and_budget(gl_ctx, cgh_file, tmp_path, capsys):
    images = {}
    for name, args in (("compute", ["--rasterizer", "compute"]), ("raster", ["--rasterizer", "raster"]),
                       ("budget", ["--budget", "270"])):  # 30 of the 60 strands, 9 Gaussians each
        out = tmp_path / f"{name}.png"
        rc, _, _ = _run(capsys, "render", cgh_file, "-o", out, "--width", 64, "--height", 48, *args)
        assert rc == 0
        images[name] = np.asarray(Image.open(out)).astype(int)
    assert images["raster"].max() > 60
    assert np.abs(images["compute"] - images["raster"]).max() <= 1  # the same image to 8 bits
    assert np.abs(images["budget"] - images["raster"]).max() > 10  # fewer, thicker strands


def test_render_verbose_names_the_driver_and_device(gl_ctx, cgh_file, tmp_path, capsys):
    rc, stdout, _ = _run(capsys, "render", cgh_file, "-o", tmp_path / "v.png", "--width", 16, "--height", 16,
                         "--verbose")
    assert rc == 0
    line = next(x for x in stdout.splitlines() if x.startswith("OpenGL: "))
    # GL_RENDERER | GL_VENDOR | GL_VERSION, and the EGL device chosen (llvmpipe's software device here)
    assert gl_ctx.info["GL_RENDERER"] in line and gl_ctx.info["GL_VENDOR"] in line
    assert gl_ctx.info["GL_VERSION"] in line and "EGL device" in line
    rc, stdout, _ = _run(capsys, "render", cgh_file, "-o", tmp_path / "q.png", "--width", 16, "--height", 16)
    assert rc == 0 and "OpenGL: " not in stdout


@pytest.mark.parametrize("command, args, message", [
    ("render", ["-o", "x.png", "--budget", "abc"], "a budget is a number of Gaussians"),
    ("render", ["-o", "x.png", "--budget", "0"], "at least 1 Gaussian"),
    ("render", ["-o", "x.png", "--rasterizer", "gpu"], "invalid choice: 'gpu'"),
    ("view", ["--budget=-5k"], "at least 1 Gaussian"),
    ("view", ["--rasterizer", "tiles"], "invalid choice: 'tiles'"),
    ("bench-viewer", ["--synthetic", "5", "--budget", "1x"], "a budget is a number of Gaussians"),
    ("bench-viewer", ["--synthetic", "5", "--rasterizer", "fast"], "invalid choice: 'fast'"),
    ("bench-viewer", ["--synthetic", "5", "--reference-size", "0", "10"], "--reference-size W must be between"),
])
def test_rasterizer_and_budget_errors(capsys, cgh_file, command, args, message):
    argv = [command, *([] if command == "bench-viewer" else [cgh_file]), *args]
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's usage errors
        rc = exc.code
    _, err = capsys.readouterr()
    assert rc == 2 and message in err and "Traceback" not in err


def test_compute_on_opengl_33_says_what_to_do(gl_ctx):
    from types import SimpleNamespace

    from viewer.context import GLContextError
    from viewer.renderer import create_renderer

    old = SimpleNamespace(version_code=330)
    asset = example_asset(seed=1, strands=4, points=4)
    with pytest.raises(GLContextError, match="--rasterizer compute needs OpenGL 4.3.*use --rasterizer raster"):
        create_renderer(old, asset, rasterizer="compute")
    with pytest.raises(GLContextError, match="--budget needs OpenGL 4.3"):
        create_renderer(old, asset, budget=1000)


@pytest.mark.parametrize("args, message", [
    ([], "either a .cgh FILE or --synthetic"),
    (["x.cgh", "--synthetic", "5"], "either a .cgh FILE or --synthetic"),
    (["--synthetic", "0"], "--synthetic must be >= 1"),
    (["--synthetic", "5", "--frames", "0"], "--frames must be >= 1"),
    (["--synthetic", "5", "--points", "1"], "--points must be >= 2"),
])
def test_bench_viewer_errors(capsys, args, message):
    rc, _, err = _run(capsys, "bench-viewer", *args)
    assert rc == 2 and message in err
