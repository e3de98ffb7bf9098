"""Hair that moves in the viewer: an animated frame's GPU decode and render equal the static ones of the
same pose; cgh render --frames / --motion writes the frames; the benchmark reports the animated split."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import cghair_format
from cghair_format import Cards, decode_gaussians
from cghair_format.animation import Animation, frame_asset, frame_points
from cghair_format.camera import Camera
from cghair_format.examples import example_asset
from viewer.decode import read_gaussians, read_points
from viewer.renderer import Renderer

pytestmark = pytest.mark.gl

POS_TOL = 2e-6  # as tests/viewer/test_gpu_decode.py: float32 GPU against float64 numpy


def _rotation_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def moving_cards(asset, frames: int = 3) -> Animation:
    """The rest pose, then the cards turned rigidly about a point, then also bent toward +x."""
    rest = asset.cards
    pivot = rest.spine[:, 0].mean(axis=0)
    out = []
    for f in range(frames):
        r = _rotation_y(0.35 * f)
        spine = (rest.spine - pivot) @ r.T + pivot
        if f >= 2:
            k = np.linspace(0, 1, spine.shape[1])[None, :, None]
            spine = spine + np.array([0.05, 0.0, 0.0]) * k ** 2
        out.append(Cards(spine.astype(np.float32), (rest.normal @ r.T).astype(np.float32), rest.half_width,
                         rest.group))
    return Animation.of_frames(out, fps=12.0, source="test")


@pytest.fixture(scope="module")
def asset():
    return example_asset(seed=3, strands=48, points=9, sh_degree=2)


def _camera(asset, width=80, height=60):
    lo, hi = asset.cards.spine.reshape(-1, 3).min(0), asset.cards.spine.reshape(-1, 3).max(0)
    return Camera.orbit((lo + hi) / 2, 2.5 * float(np.linalg.norm(hi - lo)), 20.0, 10.0, width, height, asset.up_axis)


def test_animated_decode_matches_frame_points(gl_ctx, asset):
    animation = moving_cards(asset)
    renderer = Renderer.from_asset(gl_ctx, asset, animated=True)
    try:
        for f in (2, 1, 0):
            renderer.move_cards(animation.cards(asset.cards, f))
            np.testing.assert_allclose(read_points(renderer.scene), frame_points(asset, animation, f), atol=POS_TOL)
            got, want = read_gaussians(renderer.scene), decode_gaussians(frame_asset(asset, animation, f))
            np.testing.assert_allclose(got.means, want.means, atol=POS_TOL)
            np.testing.assert_allclose(got.scales, want.scales, atol=POS_TOL)
            np.testing.assert_allclose(got.rotations, want.rotations, atol=2e-5)
            np.testing.assert_allclose(got.sh, want.sh, atol=2e-5)  # decoded once, at rest: it does not move
    finally:
        renderer.release()


@pytest.mark.parametrize("budget", [None, 96])
def test_animated_render_equals_static_render_of_the_frame(gl_ctx, asset, budget):
    """Pixels of a moved frame, at full quality and at a budget that decodes only the strands it draws
    (then grows to all: the frame decodes the rest first), against a renderer made from the moved asset
    (its SH as at rest: tests/viewer/test_viewer_sh_turn.py turns them)."""
    animation, cam = moving_cards(asset), _camera(asset)
    moving = Renderer.from_asset(gl_ctx, asset, animated=True, budget=budget, turn_sh=False)
    still = Renderer.from_asset(gl_ctx, frame_asset(asset, animation, 2), budget=budget)
    try:
        moving.move_cards(animation.cards(asset.cards, 2))
        image = moving.render(cam)
        assert image[..., 3].max() > 0.5
        np.testing.assert_array_equal(image, still.render(cam))
        moving.budget = still.budget = None
        np.testing.assert_array_equal(moving.render(cam), still.render(cam))
    finally:
        moving.release()
        still.release()


def test_static_renderer_cannot_move_cards(gl_ctx, asset):
    renderer = Renderer.from_asset(gl_ctx, asset)
    try:
        with pytest.raises(ValueError, match="animated=True"):
            renderer.move_cards(asset.cards)
    finally:
        renderer.release()


def _gif_frames(path) -> list[np.ndarray]:
    im = Image.open(path)
    frames = []
    for i in range(im.n_frames):
        im.seek(i)
        frames.append(np.asarray(im.convert("RGB")).astype(int))
    return frames


def test_render_frames_of_a_simulated_motion(gl_ctx, tmp_path):
    from cghair_format.cli import main

    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=8, strands=60, points=10, sh_degree=1), path)
    out = tmp_path / "nod.gif"
    assert main(["render", str(path), "-o", str(out), "--motion", "nod", "--frames", "2:6", "--width", "48",
                 "--height", "40"]) == 0
    frames = _gif_frames(out)
    assert len(frames) == 4
    assert max(np.abs(frames[0] - f).max() for f in frames[1:]) > 0  # the hair moves


def test_render_a_turntable_of_hair_that_moves(gl_ctx, tmp_path):
    """--turntable N with an animation: N images, the camera going round while the clip loops; image i
    is pose i % frames from the turntable's camera i."""
    from cghair_format.cli import main

    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=8, strands=60, points=10, sh_degree=1), path)
    size = ["--width", "48", "--height", "40"]
    assert main(["render", str(path), "-o", str(tmp_path / "both.gif"), "--motion", "nod", "--frames", "2:4",
                 "--turntable", "4", *size]) == 0
    assert main(["render", str(path), "-o", str(tmp_path / "moving.gif"), "--motion", "nod", "--frames", "2:4",
                 *size]) == 0
    assert main(["render", str(path), "-o", str(tmp_path / "still.gif"), "--turntable", "4", *size]) == 0
    both, moving, still = (_gif_frames(tmp_path / f"{name}.gif") for name in ("both", "moving", "still"))
    assert len(both) == 4 and len(moving) == 2
    np.testing.assert_array_equal(both[0], moving[0])  # azimuth 0, pose 2
    for i in range(1, 4):
        assert np.abs(both[i] - still[i]).max() > 0 and np.abs(both[i] - moving[i % 2]).max() > 0


def test_render_frames_to_mp4(gl_ctx, tmp_path):
    pytest.importorskip("imageio_ffmpeg", reason="MP4 output needs imageio-ffmpeg")
    import imageio.v2 as imageio

    from cghair_format.cli import main

    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=8, strands=30, points=6), path)
    out = tmp_path / "walk.mp4"
    assert main(["render", str(path), "-o", str(out), "--motion", "walk", "--frames", ":5", "--width", "32",
                 "--height", "32", "--fps", "10"]) == 0
    reader = imageio.get_reader(out)
    try:
        assert reader.count_frames() == 5 and reader.get_meta_data()["fps"] == pytest.approx(10)
    finally:
        reader.close()


def test_render_animate_reads_the_files_animation(gl_ctx, tmp_path, monkeypatch, asset):
    """Where the format package reads animations (cghair_format.read_animation, stood in for here),
    --animate renders each of its frames; with --no-turn-sh frame 2 equals the static render of that pose
    (same job), and without it the SH turn with the hair (tests/viewer/test_viewer_sh_turn.py)."""
    from cghair_format.cli import main
    from viewer.render_jobs import RenderJob, render_job

    path = tmp_path / "hair.cgh"
    cghair_format.write(asset, path)
    stored = cghair_format.read(path)
    animation = moving_cards(stored)
    monkeypatch.setattr(cghair_format, "read_animation", lambda p: animation, raising=False)
    view = ["--width", "48", "--height", "40", "--target", "0", "-0.1", "0", "--distance", "1"]
    assert main(["render", str(path), "-o", str(tmp_path / "all.gif"), "--animate", "--no-turn-sh", *view]) == 0
    assert main(["render", str(path), "-o", str(tmp_path / "turned.gif"), "--animate", *view]) == 0
    frames = _gif_frames(tmp_path / "all.gif")
    assert len(frames) == animation.frames
    job = RenderJob(width=48, height=40, target=(0.0, -0.1, 0.0), distance=1.0, turntable=1)
    render_job(frame_asset(stored, animation, 2), job, tmp_path / "still.gif", ctx=gl_ctx)
    still = _gif_frames(tmp_path / "still.gif")[0]
    assert still.max() > 40
    np.testing.assert_array_equal(frames[2], still)
    assert np.abs(frames[0] - still).mean() > 1  # not the rest pose
    assert np.abs(_gif_frames(tmp_path / "turned.gif")[2] - still).max() > 8  # the SH turned


@pytest.mark.parametrize(("args", "message"), [
    (["--frames", "0:3"], "holds no animation"),
    (["--motion", "nod", "--frames", "x:3"], "A:B or N"),
    (["--motion", "nod", "--frames", "5:3"], "selects no frame"),
    (["--motion", "nod", "--animate", "--frames", "0:2"], "leave out --frames"),
])
def test_render_frames_bad_arguments(gl_ctx, tmp_path, capsys, args, message):
    from cghair_format.cli import main

    path = tmp_path / "hair.cgh"
    cghair_format.write(example_asset(seed=8, strands=30, points=6), path)
    assert main(["render", str(path), "-o", str(tmp_path / "a.gif"), "--width", "16", "--height", "16", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "a.gif").exists()


@pytest.mark.parametrize(("simulate", "turn_sh"), [(False, True), (True, True), (False, False)])
def test_bench_reports_the_animated_split(gl_ctx, simulate, turn_sh):
    from viewer.bench import benchmark, format_report

    result = benchmark(synthetic=60, points=11, width=64, height=48, frames=1, rasterizers=("compute",),
                       budgets=(200,), reference_size=None, ctx=gl_ctx, animate=True, simulate=simulate,
                       turn_sh=turn_sh)
    assert result["animated"]["turn_sh"] is turn_sh
    assert ("SH turned with their segments" if turn_sh else "SH not turned") in format_report(result)
    runs = result["animated"]["runs"]
    assert [r["budget"] for r in runs] == [None, 200]
    for run in runs:
        stages = {"upload_s", "decode_s", "preprocess_s", "sort_s", "gather_s", "draw_s"}
        assert stages | ({"simulate_s"} if simulate else set()) == set(run["animated"])
        assert run["animated_frame_s"] == pytest.approx(sum(run["animated"].values()))
        assert run["animated_over_static"] == pytest.approx(run["animated_frame_s"] / run["static_frame_s"])
    assert "animated/static" in format_report(result)


@pytest.mark.parametrize("turn_sh", [True, False])
def test_bench_compares_the_animated_appearance(gl_ctx, tmp_path, monkeypatch, asset, turn_sh):
    """With the reference, bench-viewer --animate reports the PSNR of frames of the file's clip against the
    native splatter on frame_gaussians(turn_sh=True): the viewer's frame close to it where it turns the SH,
    about as far as the unturned SH where it does not."""
    pytest.importorskip("torch", reason="the reference renders need torch")
    from viewer.bench import benchmark, format_report

    path = tmp_path / "hair.cgh"
    cghair_format.write(asset, path)
    animation = moving_cards(cghair_format.read(path))
    monkeypatch.setattr(cghair_format, "read_animation", lambda p: animation, raising=False)
    result = benchmark(path=str(path), width=64, height=48, frames=1, rasterizers=("compute",), budgets=(200,),
                       reference_size=(80, 60), ctx=gl_ctx, animate=True, turn_sh=turn_sh)
    rows = result["animated"]["psnr"]
    assert [r["frame"] for r in rows] == [0, 1, 2]  # of the clip's 3 frames
    assert "the viewer's frame | SH left unturned" in format_report(result)
    for row in rows[1:]:
        assert row["unturned_db"] < 60  # the hair turned: the SH left as at rest are visibly off
        if turn_sh:
            assert row["viewer_db"] > row["unturned_db"] + 10
        else:
            assert abs(row["viewer_db"] - row["unturned_db"]) < 3
