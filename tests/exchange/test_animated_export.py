"""Animated exports: a tiny asset whose cards turn rigidly about a point by a known angle per frame.

USD is read back with usd-core, Alembic with the independent reader in ``abc_reader.py``; every
frame's samples must equal the frame's decode (:func:`frame_points`, the moved card mesh and
Gaussians) exactly, and lie where the rigid turn puts the rest pose (an independent check of what
moved). Blender plays both (``@pytest.mark.blender``).
"""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from abc_reader import Archive

import cghair_format
from cghair_format.animation import Animation, frame_asset, frame_points
from cghair_format.cli import main
from cghair_format.errors import CghError
from cghair_format.examples import example_asset
from cghair_format.exchange.alembic import export_groom, to_alembic_frame, write_asset_groom
from cghair_format.exchange.animated import frame_range
from cghair_format.exchange.blender import BlenderNotFoundError, find_blender_python
from cghair_format.exchange.cgh_strands import strands_from_asset
from cghair_format.exchange.usd_export import export_usd
from cghair_format.gaussians import gaussian_frames
from cghair_format.geometry import card_mesh

pxr = pytest.importorskip("pxr", reason="USD tests need usd-core: pip install -e '.[usd]'")
from pxr import Usd, UsdGeom  # noqa: E402

FRAMES, FPS, START, STEP = 6, 24.0, 0.5, 0.15  # STEP: radians turned per frame


def turn(angle: float) -> np.ndarray:
    """The rotation by ``angle`` about the axis (1, 2, 2) / 3."""
    axis = np.array([1.0, 2.0, 2.0]) / 3
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


@pytest.fixture(scope="module")
def asset():
    return example_asset(seed=4, strands=30, points=7, sh_degree=1)


def pivot(asset) -> np.ndarray:
    return asset.cards.spine.reshape(-1, 3).mean(0).astype(np.float64)


def turning(asset, frames: int = FRAMES) -> Animation:
    """The asset's cards turned by ``STEP * f`` about :func:`pivot` at frame ``f``."""
    p, rot = pivot(asset), [turn(STEP * f) for f in range(frames)]
    spine = np.stack([(asset.cards.spine - p) @ r.T + p for r in rot]).astype(np.float32)
    normal = np.stack([asset.cards.normal @ r.T for r in rot]).astype(np.float32)
    return Animation(spine, normal, FPS, START, "test turn")


def rest_turned(asset, f: int) -> np.ndarray:
    """The rest pose's strand points turned as frame ``f`` turns the cards (float64)."""
    return (strands_from_asset(asset).points - pivot(asset)) @ turn(STEP * f).T + pivot(asset)


def test_usd_time_samples_are_each_frames_decode(tmp_path, asset):
    anim = turning(asset)
    path = tmp_path / "a.usdc"
    export_usd(path, asset=asset, cards=True, gaussians=True, animation=anim)
    stage = Usd.Stage.Open(str(path))
    assert stage.GetTimeCodesPerSecond() == FPS == stage.GetFramesPerSecond()
    codes = [START * FPS + f for f in range(FRAMES)]
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (codes[0], codes[-1])
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Hair/Strands"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Hair/Cards"))
    splat = stage.GetPrimAtPath("/Hair/Gaussians")
    points = UsdGeom.Points(stage.GetPrimAtPath("/Hair/GaussianPoints"))
    for attr in (curves.GetPointsAttr(), mesh.GetPointsAttr(), mesh.GetNormalsAttr(), splat.GetAttribute("positions"),
                 splat.GetAttribute("orientations"), points.GetPointsAttr(), curves.GetExtentAttr()):
        assert attr.GetTimeSamples() == codes, attr.GetName()
    assert not curves.GetCurveVertexCountsAttr().GetTimeSamples()  # the topology stays the rest pose's
    diag = float(np.linalg.norm(np.ptp(strands_from_asset(asset).points, 0)))
    for f, t in enumerate(codes):
        got = np.asarray(curves.GetPointsAttr().Get(t))
        np.testing.assert_array_equal(got, frame_points(asset, anim, f)[asset.real_points()])
        np.testing.assert_allclose(got, rest_turned(asset, f), rtol=0, atol=1e-5 * diag)
        np.testing.assert_array_equal(np.asarray(curves.GetExtentAttr().Get(t)), [got.min(0), got.max(0)])
        m = card_mesh(anim.cards(asset.cards, f))
        np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get(t)), m.vertices)
        np.testing.assert_array_equal(np.asarray(mesh.GetNormalsAttr().Get(t)), m.normals)
        means, rotations, scales, _ = gaussian_frames(frame_asset(asset, anim, f))
        np.testing.assert_array_equal(np.asarray(splat.GetAttribute("positions").Get(t)), means)
        np.testing.assert_array_equal(np.asarray(splat.GetAttribute("orientations").Get(t)), rotations[:, [1, 2, 3, 0]])
        np.testing.assert_array_equal(np.asarray(splat.GetAttribute("scales").Get(t)), scales)
        np.testing.assert_array_equal(np.asarray(points.GetPointsAttr().Get(t)), means)
    # a reader that asks for no time still finds the rest pose
    np.testing.assert_array_equal(np.asarray(curves.GetPointsAttr().Get(Usd.TimeCode.Default())),
                                  strands_from_asset(asset).points)


def test_usd_scale_and_frame_range_keep_times(tmp_path, asset):
    anim = frame_range(turning(asset), "2:5")
    assert (anim.frames, anim.start) == (3, START + 2 / FPS)
    path = tmp_path / "a.usda"
    export_usd(path, asset=asset, animation=anim, scale=100)
    stage = Usd.Stage.Open(str(path))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Hair/Strands"))
    full = turning(asset)
    assert curves.GetPointsAttr().GetTimeSamples() == [START * FPS + f for f in (2, 3, 4)]
    for f in (2, 3, 4):  # each frame keeps its time code
        np.testing.assert_array_equal(np.asarray(curves.GetPointsAttr().Get(START * FPS + f)),
                                      frame_points(asset, full, f)[asset.real_points()] * np.float32(100))


@pytest.mark.parametrize("spec,frames", [("1:", [1, 2, 3, 4, 5]), (":2", [0, 1]), ("-2:", [4, 5]), ("3:4", [3])])
def test_frame_range(asset, spec, frames):
    anim = frame_range(turning(asset), spec)
    np.testing.assert_array_equal(anim.spine, turning(asset).spine[frames])
    assert anim.start == START + frames[0] / FPS


@pytest.mark.parametrize("spec", ["3", "a:b", "1:2:3", "4:2", "9:"])
def test_bad_frame_range(asset, spec):
    with pytest.raises(CghError, match="--frames"):
        frame_range(turning(asset), spec)


def groom_cache(path):
    a = Archive(path)
    return a, a.top.children["Strands"].children["StrandsShape"].props[".geom"].props


def test_alembic_groom_cache_samples(tmp_path, asset):
    anim = turning(asset)
    path = tmp_path / "a.abc"
    write_asset_groom(path, asset, scale=100, cards=True, animation=anim)
    a, geom = groom_cache(path)
    assert [(t.max_samples, t.time_per_cycle, t.times) for t in a.time_samplings] == [(1, 1.0, (0.0,)),
                                                                                      (FRAMES, 1 / FPS, (START,))]
    assert a.metadata["_ai_DCC_FPS"] == "24.0"
    k = 100 * asset.meters_per_unit
    p = geom["P"]
    assert (p.time_sampling, p.samples, p.changed, len(p.stored)) == (1, FRAMES, (1, FRAMES - 1), FRAMES)
    for f in range(FRAMES):
        want = to_alembic_frame(frame_points(asset, anim, f)[asset.real_points()], asset.up_axis, k)
        np.testing.assert_array_equal(p.sample(f), want)
        np.testing.assert_array_equal(geom[".selfBnds"].sample(f)[0], np.r_[want.min(0), want.max(0)])
    # everything else is constant on the same sampling: stored once
    for prop in [geom["nVertices"], geom["width"], geom["curveBasisAndType"],
                 *geom[".arbGeomParams"].props.values()]:
        assert (prop.time_sampling, prop.samples, prop.changed, len(prop.stored)) == (1, FRAMES, (0, 0), 1)
    assert a.top.children["Strands"].props[".xform"].props[".inherits"].time_sampling == 0
    cards = a.top.children["Cards"].children["CardsShape"].props[".geom"].props
    for f in range(FRAMES):
        m = card_mesh(anim.cards(asset.cards, f))
        np.testing.assert_array_equal(cards["P"].sample(f), to_alembic_frame(m.vertices, asset.up_axis, k))
        np.testing.assert_array_equal(cards["N"].sample(f), to_alembic_frame(m.normals, asset.up_axis))
    assert len(cards[".faceIndices"].stored) == len(cards["uv"].stored) == 1


def test_alembic_held_frames_are_stored_once(tmp_path, asset):
    """A pose held for frames 0-2 and 3-5: each sample index still finds its frame, and the held
    frames share their data (the file holds two poses, not six)."""
    moving = turning(asset)
    held = Animation(moving.spine[[0, 0, 0, 3, 3, 3]], moving.normal[[0, 0, 0, 3, 3, 3]], FPS)
    still = Animation(moving.spine[[0] * 6], moving.normal[[0] * 6], FPS)
    sizes = {}
    for name, anim in (("held", held), ("still", still)):
        write_asset_groom(tmp_path / f"{name}.abc", asset, animation=anim)
        sizes[name] = (tmp_path / f"{name}.abc").stat().st_size
        a, geom = groom_cache(tmp_path / f"{name}.abc")
        for f in range(6):
            want = to_alembic_frame(frame_points(asset, anim, f)[asset.real_points()], asset.up_axis,
                                    asset.meters_per_unit)
            np.testing.assert_array_equal(geom["P"].sample(f), want)
    assert geom["P"].changed == (0, 0) and a.time_samplings[1].max_samples == 1  # still: constant
    n_bytes = 12 * len(strands_from_asset(asset).points)
    assert n_bytes < sizes["held"] - sizes["still"] < 2 * n_bytes  # one more pose, not four


def test_static_exports_take_no_time_sampling(tmp_path, asset):
    export_groom(tmp_path / "s.abc", asset=asset, cards=True)
    a, geom = groom_cache(tmp_path / "s.abc")
    assert len(a.time_samplings) == 1 and geom["P"].time_sampling == 0 and "_ai_DCC_FPS" not in a.metadata
    export_usd(tmp_path / "s.usda", asset=asset)
    assert "timeCodesPerSecond" not in (tmp_path / "s.usda").read_text()


def test_bad_animations_are_refused(tmp_path, asset):
    anim = turning(asset)
    other = Animation(anim.spine[:, :-1], anim.normal[:, :-1], FPS)  # a card short
    nan = Animation(anim.spine.copy(), anim.normal, FPS)
    nan.spine[2, 0, 0, 0] = np.nan
    (tmp_path / "old.abc").write_bytes(b"keep me")
    for bad, match in ((other, "animation frames must be"), (nan, "frame 2 holds NaN")):
        with pytest.raises(CghError, match=match):
            export_usd(tmp_path / "x.usdc", asset=asset, animation=bad)
        with pytest.raises(CghError, match=match):
            write_asset_groom(tmp_path / "old.abc", asset, animation=bad)
    assert not (tmp_path / "x.usdc").exists() and (tmp_path / "old.abc").read_bytes() == b"keep me"
    with pytest.raises(CghError, match="plain strands"):
        export_usd(tmp_path / "x.usdc", strands=strands_from_asset(asset), animation=anim)
    with pytest.raises(CghError, match="rest pose only"):
        export_groom(tmp_path / "x.blend", asset=asset, animation=anim)


def test_interrupted_alembic_export_keeps_the_old_file(tmp_path, asset, monkeypatch):
    import cghair_format.exchange.alembic as abc

    path = tmp_path / "old.abc"
    path.write_bytes(b"keep me")
    anim = turning(asset)

    def broken(asset_, animation, f):
        if f == 3:
            raise KeyboardInterrupt
        return frame_points(asset_, animation, f)[asset_.real_points()]

    monkeypatch.setattr("cghair_format.exchange.animated.curve_points", broken)
    with pytest.raises(KeyboardInterrupt):
        abc.write_asset_groom(path, asset, animation=anim)
    assert path.read_bytes() == b"keep me" and [p.name for p in tmp_path.iterdir()] == ["old.abc"]


@pytest.fixture
def animated_cgh(tmp_path, asset, monkeypatch):
    """A .cgh whose animation ``cghair_format.read_animation`` hands out (the animation part's reader
    is another module's work: stood in for here)."""
    path = tmp_path / "a.cgh"
    cghair_format.write(asset, path)
    monkeypatch.setattr(cghair_format, "read_animation", lambda p: turning(asset) if p == path else None,
                        raising=False)
    return path


def test_cli_exports_the_animation(tmp_path, asset, animated_cgh, capsys):
    out = tmp_path / "a.usdc"
    assert main(["export", str(animated_cgh), "-o", str(out), "--frames", "1:4", "--cards"]) == 0
    assert "at 3 frames (24 fps)" in capsys.readouterr().out
    stage = Usd.Stage.Open(str(out))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Hair/Strands"))
    assert curves.GetPointsAttr().GetTimeSamples() == [START * FPS + f for f in (1, 2, 3)]
    assert main(["export", str(animated_cgh), "-o", str(tmp_path / "a.abc")]) == 0
    assert groom_cache(tmp_path / "a.abc")[1]["P"].samples == FRAMES
    assert main(["export", str(animated_cgh), "-o", str(tmp_path / "r.usda"), "--rest"]) == 0
    assert "timeCodesPerSecond" not in (tmp_path / "r.usda").read_text()


@pytest.mark.parametrize("extra,match", [(["--frames", "7:9"], "selects no frame"),
                                         (["--frames", "x"], "A:B"),
                                         (["--frames", "1:2", "--rest"], "give one"),
                                         (["-o", "OUT.blend"], "add --rest"),
                                         (["-o", "OUT.ply", "--frames", "0:1"], "one pose")])
def test_cli_bad_animation_arguments(tmp_path, animated_cgh, capsys, extra, match):
    out = ["-o", str(tmp_path / "a.usda")]
    if "-o" in extra:
        out, extra = ["-o", str(tmp_path / extra[1].replace("OUT", "a"))], extra[2:]
    assert main(["export", str(animated_cgh), *out, *extra]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_cli_frames_of_a_still_asset(tmp_path, asset, capsys):
    path = tmp_path / "s.cgh"
    cghair_format.write(asset, path)
    assert main(["export", str(path), "-o", str(tmp_path / "s.usda"), "--frames", "0:2"]) == 2
    assert "has no animation" in capsys.readouterr().err


BLENDER_PLAY = r"""
import json, sys
import bpy
import numpy as np

path, fps, frames = sys.argv[-3], int(sys.argv[-2]), json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps, scene.render.fps_base = fps, 1.0
if path.endswith(".abc"):
    bpy.ops.wm.alembic_import(filepath=path)
else:
    bpy.ops.wm.usd_import(filepath=path)
report = {"range": [scene.frame_start, scene.frame_end], "frames": {}}
for frame in frames:
    scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for o in bpy.data.objects:
        if o.type not in ("CURVES", "MESH"):
            continue
        ev = o.evaluated_get(depsgraph)
        d = ev.data
        if o.type == "CURVES":
            pos = np.empty(len(d.points) * 3, np.float32)
            d.attributes["position"].data.foreach_get("vector", pos)
        else:
            pos = np.empty(len(d.vertices) * 3, np.float32)
            d.vertices.foreach_get("co", pos)
        world = np.array(ev.matrix_world, np.float64)
        pos = pos.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3]
        report["frames"].setdefault(str(frame), {})[o.name] = pos.tolist()
print("CGH_REPORT " + json.dumps(report))
"""


@pytest.mark.blender
@pytest.mark.slow
@pytest.mark.parametrize("ext", [".usdc", ".abc"])
def test_blender_plays_the_animation(tmp_path, asset, ext):
    """Blender imports the animated export and, at two frames (frame_set), shows the strands (and the
    cards) where the animation puts them, in Blender's z-up world."""
    try:
        python = find_blender_python()
    except BlenderNotFoundError as exc:
        pytest.fail(f"{exc}. Deselect this test with -m 'not blender'.")
    anim = Animation(turning(asset).spine, turning(asset).normal, FPS, 0.0)  # frame f at scene frame f
    path = tmp_path / f"a{ext}"
    if ext == ".abc":
        write_asset_groom(path, asset, cards=True, animation=anim)
    else:
        export_usd(path, asset=asset, cards=True, animation=anim)
    frames = [1, 4]
    proc = subprocess.run([python, "-c", BLENDER_PLAY, str(path), str(int(FPS)), json.dumps(frames)],
                          capture_output=True, text=True, timeout=300)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("CGH_REPORT ")]
    assert proc.returncode == 0 and lines, f"Blender failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    report = json.loads(lines[-1][len("CGH_REPORT "):])
    y_up_to_z_up = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)
    k = asset.meters_per_unit if ext == ".abc" else 1.0  # Alembic is in metres; USD keeps the units
    diag = float(np.linalg.norm(np.ptp(strands_from_asset(asset).points, 0))) * k
    for f in frames:
        got = report["frames"][str(f)]
        strands = frame_points(asset, anim, f)[asset.real_points()].astype(np.float64) * k @ y_up_to_z_up.T
        cards = card_mesh(anim.cards(asset.cards, f)).vertices.astype(np.float64) * k @ y_up_to_z_up.T
        np.testing.assert_allclose(np.asarray(got["Strands"]), strands, rtol=0, atol=1e-5 * diag)
        np.testing.assert_allclose(np.asarray(got["Cards"]), cards, rtol=0, atol=1e-5 * diag)
