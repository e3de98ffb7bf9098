"""NeRF-synthetic datasets: write/read round trip, the train / val / test split, the splat engine,
bad folders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cghair_format.camera import Camera
from training.datasets.layouts import detect_layout
from training.datasets.nerf import write_dataset
from training.datasets.read import read_dataset
from training.datasets.synthetic import reference_gaussians, render_dataset
from training.datasets.types import Dataset, DatasetError, View, split_indices


def _views(n, res=10, seed=0, first_angle=0.0):
    rng = np.random.default_rng(seed)
    return [View(Camera.orbit((0, 0, 0), 3.0, first_angle + 40.0 * i, 10.0, res, res),
                 rng.random((res, res, 4)).astype(np.float32), f"r_{i:03d}") for i in range(n)]


def test_round_trip(tmp_path):
    ds = Dataset(_views(3), _views(2, seed=1), {"engine": "test"}, _views(1, seed=2, first_angle=20.0))
    write_dataset(tmp_path, ds)
    back = read_dataset(tmp_path)
    assert [v.name for v in back.train] == ["r_000", "r_001", "r_002"] and len(back.test) == 2
    assert len(back.val) == 1 and (tmp_path / "transforms_val.json").is_file()
    assert back.meta == {"engine": "test"}
    for a, b in zip(ds.train + ds.val + ds.test, back.train + back.val + back.test, strict=True):
        assert np.abs(a.image - b.image).max() <= 0.5 / 255 + 1e-6  # 8-bit PNG rounding
        assert np.allclose(a.camera.world_to_camera, b.camera.world_to_camera, atol=1e-9)
        assert np.isclose(a.camera.fx, b.camera.fx) and a.camera.width == b.camera.width
    doc = json.loads((tmp_path / "transforms_train.json").read_text())
    assert doc["frames"][0]["file_path"] == "./train/r_000"


def test_split_indices():
    train, val, test = split_indices(16)
    assert test == [7, 15] and val == [3, 11] and len(train) == 12
    assert sorted(train + val + test) == list(range(16))  # disjoint, and every view in one split
    assert split_indices(32)[1:] == ([3, 11, 19, 27], [7, 15, 23, 31])
    assert split_indices(5) == ([0, 1, 2], [3], [4])
    # too few views to spare one for validation: none, and at least one to train on
    assert split_indices(4) == ([0, 1, 2], [], [3])
    assert split_indices(2) == ([0], [], [1])


def test_a_dataset_without_val_views_falls_back_to_train(tmp_path):
    write_dataset(tmp_path, Dataset(_views(3), _views(1, seed=1)))
    assert not (tmp_path / "transforms_val.json").exists()
    ds = read_dataset(tmp_path)
    assert ds.val == [] and "no val views" in detect_layout(tmp_path).describe()
    with pytest.warns(UserWarning, match="no validation views: using its training views"):
        assert ds.split("val") is ds.train
    assert ds.split("test") is ds.test
    with pytest.raises(DatasetError, match="choose train, val, test"):
        ds.split("held-out")


def test_val_views_that_are_test_views_are_refused(tmp_path):
    write_dataset(tmp_path, Dataset(_views(3), _views(2, seed=1), {}, _views(2, seed=2, first_angle=20.0)))
    assert len(read_dataset(tmp_path).val) == 2
    write_dataset(tmp_path, Dataset(_views(3), _views(2, seed=1), {}, _views(1, seed=2)))  # test view 0's pose
    with pytest.raises(DatasetError, match="1 validation views .* have the pose of a test view"):
        read_dataset(tmp_path)
    write_dataset(tmp_path, Dataset(_views(3), _views(2, seed=1)))  # rewritten without val: none left behind
    assert read_dataset(tmp_path).val == [] and not (tmp_path / "transforms_val.json").exists()


def test_bad_folders(tmp_path):
    with pytest.raises(DatasetError, match="does not exist"):
        read_dataset(tmp_path / "nope")
    with pytest.raises(DatasetError, match="expected transforms_train.json"):
        read_dataset(tmp_path)
    write_dataset(tmp_path, Dataset(_views(2), _views(1)))
    (tmp_path / "train" / "r_001.png").unlink()
    with pytest.raises(DatasetError, match="r_001.png is missing"):
        read_dataset(tmp_path)
    (tmp_path / "transforms_train.json").write_text("{not json")
    with pytest.raises(DatasetError, match="malformed"):
        read_dataset(tmp_path)
    (tmp_path / "transforms_train.json").write_text(json.dumps(
        {"camera_angle_x": 0.7, "frames": [{"file_path": "./train/r_000", "transform_matrix": [[1, 0], [0, 1]]}]}))
    with pytest.raises(DatasetError, match="4x4"):
        read_dataset(tmp_path)


def test_render_splat_dataset(tmp_path, strands):
    ds = render_dataset(strands, tmp_path, views=8, res=24, engine="splat")
    assert [v.name for v in ds.val] == ["r_003"] and [v.name for v in ds.test] == ["r_007"] and len(ds.train) == 6
    back = read_dataset(tmp_path)
    assert [v.name for v in back.val] == ["r_003"] and "transforms_val.json" in detect_layout(tmp_path).describe()
    for v in back.train + back.val + back.test:
        mask = v.image[..., 3]
        assert 0.03 < mask.mean() < 0.9  # the hair is in frame, not filling it
        assert mask[0].max() < 0.5 and mask[:, 0].max() < 0.5  # the framing leaves a border
    assert back.meta["engine"] == "splat" and back.meta["thickness"] > 0


def test_reference_gaussians_variable_lengths(strands):
    from cghair_format.strands import Strands

    pts = strands.points[: 5 + 7]
    s = Strands(pts, np.array([0, 5, 12]))
    g = reference_gaussians(s, 0.01, seed=0)
    assert g.count == 4 + 6  # no segment between strands
    assert g.sh.shape == (10, 4, 3) and np.allclose(g.sh[:4, 1:], g.sh[0, 1:])  # band 1 per strand


def test_render_dataset_bad_options(tmp_path, strands):
    with pytest.raises(DatasetError, match="engine"):
        render_dataset(strands, tmp_path, engine="povray")
    with pytest.raises(DatasetError, match="preset"):
        render_dataset(strands, tmp_path, preset="green")
    with pytest.raises(DatasetError, match="at least 2 views"):
        render_dataset(strands, tmp_path, views=1)


def test_multitone_colours_are_ordered_segments(strands):
    from cghair_format.synth import melanin_rgb
    from training.datasets.colours import MULTITONE_MELANIN, multitone_colours

    for tones in (2, 3, 4):
        rgb = multitone_colours(strands, tones, seed=1)
        palette = melanin_rgb(*np.asarray(MULTITONE_MELANIN[:tones]).T)
        unit = palette / np.linalg.norm(palette, axis=1, keepdims=True)
        for i in range(strands.count):
            c = rgb[strands.offsets[i]:strands.offsets[i + 1]].astype(np.float64)
            tone = np.argmax((c / np.linalg.norm(c, axis=1, keepdims=True)) @ unit.T, 1)
            assert tone[0] == 0 and tone[-1] == tones - 1  # root tone first, tip tone last
            assert np.all(np.diff(tone) >= 0)  # segments in order along the strand
            # every point is its palette tone times one brightness per strand (clipped at 1)
            scale = c / palette[tone]
            ok = (c < 1).all(1)
            np.testing.assert_allclose(scale[ok], scale[ok][0, 0], rtol=1e-5)
    with pytest.raises(DatasetError, match="2 to 4 tones"):
        multitone_colours(strands, 5)


def test_multitone_changes_the_splat_ground_truth(tmp_path, strands):
    plain = render_dataset(strands, tmp_path / "p", views=2, res=32)
    multi = render_dataset(strands, tmp_path / "m", views=2, res=32, multitone=3)
    assert multi.meta["multitone"] == 3 and plain.meta["multitone"] == 0
    np.testing.assert_array_equal(multi.train[0].image[..., 3], plain.train[0].image[..., 3])  # same geometry
    hair = plain.train[0].image[..., 3] > 0.5
    assert np.abs(multi.train[0].image[..., :3] - plain.train[0].image[..., :3])[hair].mean() > 0.05


def test_prepare_strands_reaches_the_requested_scale(strands):
    from training.datasets.synthetic import prepare_strands

    out = prepare_strands(strands, points=10, count=300, seed=0)
    assert out.count == 300 and np.all(out.point_counts == 10)
    assert prepare_strands(strands) is strands


def test_cli_paper_scale_options(tmp_path, strands_file, capsys):
    from cghair_format.cli import main

    out = tmp_path / "ds"
    assert main(["render-dataset", str(strands_file), "-o", str(out), "--resample", "8", "--densify", "200",
                 "--multitone", "--views", "9", "--res", "32", "--no-progress"]) == 0
    assert "7 train + 1 val + 1 test views (32 x 32, engine splat, 200 strands)" in capsys.readouterr().out
    meta = json.loads((out / "dataset.json").read_text())
    assert (meta["strands"], meta["points"], meta["multitone"]) == (200, 8, 3)
    with pytest.raises(SystemExit):
        main(["render-dataset", str(strands_file), "-o", str(out), "--multitone", "5"])


def test_the_dataset_modules_import_in_one_direction():
    """training/datasets/: each module imports (at any depth of its code) only the package's modules
    listed before it in the package docstring's order, and nothing else of training but the rasterizers."""
    import ast
    from pathlib import Path

    import training.datasets

    order = ["types", "colmap", "nerf", "layouts", "capture", "read", "alignment", "cameras", "colours", "cycles",
             "synthetic"]
    folder = Path(training.datasets.__file__).parent
    assert sorted(p.stem for p in folder.glob("*.py") if p.stem != "__init__") == sorted(order)
    for k, name in enumerate(order):
        for node in ast.walk(ast.parse((folder / f"{name}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                target = node.module or node.names[0].name
                assert target in order[:k], f"datasets.{name} imports datasets.{target}"
            elif isinstance(node, ast.ImportFrom) and node.level == 2:
                assert node.module in ("backends", "splatter"), f"datasets.{name} imports training.{node.module}"
            elif isinstance(node, ast.ImportFrom | ast.Import):
                modules = [node.module] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
                assert not any(m and m.split(".")[0] in ("training", "viewer") for m in modules), (name, modules)
