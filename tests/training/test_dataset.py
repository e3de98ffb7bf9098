"""NeRF-synthetic datasets: write/read round trip, the splat engine, bad folders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cghair_format.camera import Camera
from training.dataset import (
    Dataset,
    DatasetError,
    View,
    read_dataset,
    reference_gaussians,
    render_dataset,
    split_indices,
    write_dataset,
)


def _views(n, res=10, seed=0):
    rng = np.random.default_rng(seed)
    return [View(Camera.orbit((0, 0, 0), 3.0, 40.0 * i, 10.0, res, res),
                 rng.random((res, res, 4)).astype(np.float32), f"r_{i:03d}") for i in range(n)]


def test_round_trip(tmp_path):
    ds = Dataset(_views(3), _views(2, seed=1), {"engine": "test"})
    write_dataset(tmp_path, ds)
    back = read_dataset(tmp_path)
    assert [v.name for v in back.train] == ["r_000", "r_001", "r_002"] and len(back.test) == 2
    assert back.meta == {"engine": "test"}
    for a, b in zip(ds.train + ds.test, back.train + back.test, strict=True):
        assert np.abs(a.image - b.image).max() <= 0.5 / 255 + 1e-6  # 8-bit PNG rounding
        assert np.allclose(a.camera.world_to_camera, b.camera.world_to_camera, atol=1e-9)
        assert np.isclose(a.camera.fx, b.camera.fx) and a.camera.width == b.camera.width
    doc = json.loads((tmp_path / "transforms_train.json").read_text())
    assert doc["frames"][0]["file_path"] == "./train/r_000"


def test_split_indices():
    train, test = split_indices(16)
    assert test == [7, 15] and len(train) == 14 and not set(train) & set(test)
    assert split_indices(4) == ([0, 1, 2], [3])


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
    assert len(ds.train) == 7 and len(ds.test) == 1
    back = read_dataset(tmp_path)
    for v in back.train + back.test:
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
