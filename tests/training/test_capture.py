"""Real captures as input: COLMAP and GaussianHaircut layouts read as the same views as the NeRF
layout they were converted from, the frame check, and each bad input as a one-line error."""

from __future__ import annotations

import shutil
import struct
from dataclasses import replace

import numpy as np
import pytest
import torch
from training_helpers import hair_cap, nerf_to_colmap

from cghair_format.cli import main
from cghair_format.exchange import save_strands
from training.config import TrainConfig
from training.datasets.alignment import check_strands_in_views, fraction_in_masks, solid_share
from training.datasets.colmap import ColmapError, read_model
from training.datasets.layouts import detect_layout
from training.datasets.nerf import write_dataset
from training.datasets.read import read_dataset
from training.datasets.synthetic import render_dataset
from training.datasets.types import Dataset, DatasetError, View
from training.evaluate import evaluate_model
from training.train import train

pycolmap_needed = pytest.mark.skipif(
    not __import__("importlib").util.find_spec("pycolmap"),
    reason="pycolmap (the dev extra) writes the COLMAP models of these tests")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A 12-view 64 x 64 splat dataset of 300 strands, and its strands."""
    root = tmp_path_factory.mktemp("scene")
    strands = hair_cap(300, 12, seed=2)
    render_dataset(strands, root / "nerf", views=12, res=64, engine="splat")
    return root, strands


def _same_views(a, b):
    assert [v.name for v in a.train] == [v.name for v in b.train]
    assert [v.name for v in a.val] == [v.name for v in b.val]
    assert [v.name for v in a.test] == [v.name for v in b.test]
    for va, vb in zip(a.train + a.val + a.test, b.train + b.val + b.test, strict=True):
        ca, cb = va.camera, vb.camera
        assert (ca.width, ca.height, ca.fx, ca.fy, ca.cx, ca.cy) == (cb.width, cb.height, cb.fx, cb.fy, cb.cx, cb.cy)
        # the pose goes through a quaternion: equal to float64 rounding
        assert np.abs(ca.world_to_camera - cb.world_to_camera).max() < 1e-13
        assert np.array_equal(va.image, vb.image)  # RGB and mask, bit for bit


@pycolmap_needed
@pytest.mark.parametrize("form", ["binary", "text", "haircut"])
def test_capture_reads_the_same_views(scene, tmp_path, form):
    root, _ = scene
    nerf_to_colmap(root / "nerf", tmp_path, text=form == "text", haircut=form == "haircut",
                   scale=2 if form == "haircut" else 1)
    layout = detect_layout(tmp_path)
    assert layout.name == ("GaussianHaircut" if form == "haircut" else "COLMAP")
    assert ("images_2/" if form == "haircut" else "images/") in layout.describe()
    assert (".txt" if form == "text" else ".bin") in layout.describe()
    nerf, capture = read_dataset(root / "nerf"), read_dataset(tmp_path)
    # every 8th view held out for testing and every 8th from the 4th for validation, as render-dataset does
    assert [v.name for v in capture.val] == ["r_003", "r_011"] and [v.name for v in capture.test] == ["r_007"]
    assert len(capture.train) == 9
    _same_views(nerf, capture)


def _tiny_config() -> TrainConfig:
    return TrainConfig(iterations=20, n_cards=12, n_groups=3, points_per_strand=8, card_segments=6,
                       codebook_size=4, latent_dim=16, mlp_hidden=[32], sh_degree=1, geometry_frozen_iters=10,
                       log_every=10, checkpoint_every=1000)


@pytest.mark.slow
@pycolmap_needed
def test_capture_trains_to_the_same_psnr(scene, tmp_path):
    root, strands = scene
    nerf_to_colmap(root / "nerf", tmp_path / "colmap")
    torch.set_num_threads(1)
    psnr = []
    for folder in (root / "nerf", tmp_path / "colmap"):
        result = train(folder, strands=strands, config=_tiny_config(), progress=False)
        ds = read_dataset(folder)
        psnr.append((result.history[-1]["psnr"], evaluate_model(result.model, ds.test, "soft", 0.1).psnr))
    (train_a, test_a), (train_b, test_b) = psnr
    assert abs(train_a - train_b) < 1e-3 and abs(test_a - test_b) < 1e-3, psnr
    assert test_a > 10  # the run fitted something


def test_frame_check(scene):
    root, strands = scene
    views = read_dataset(root / "nerf").train
    pts = strands.points.astype(np.float64)
    assert check_strands_in_views(pts, views) > 0.9
    # out of view, in centimetres, moved by about the hair's half height (a rotation that leaves
    # this near-symmetric cap where it was is not caught: the check compares silhouettes)
    for moved in (pts + [0.0, 5.0, 0.0], pts * 100.0, pts + [0.0, 1.0, 0.0]):
        with pytest.raises(DatasetError, match="not in the same frame"):
            check_strands_in_views(moved, views)
    behind = fraction_in_masks(pts, views[:1])
    assert behind.shape == (1,) and 0.9 < behind[0] <= 1.0


@pycolmap_needed
def test_real_hair_capture(tmp_path):
    """A subset of Ratboy mohawk (318 strands x 32 points), splat-rendered, as NeRF and as COLMAP."""
    from hairdata import hair_path

    from cghair_format.exchange import load_strands
    from cghair_format.strands import Strands

    full = load_strands(hair_path("Ratboy_mohawk.tfx"))
    strands = Strands.from_array(full.to_array()[::7])
    render_dataset(strands, tmp_path / "nerf", views=12, res=64, engine="splat")
    nerf_to_colmap(tmp_path / "nerf", tmp_path / "colmap")
    nerf, capture = read_dataset(tmp_path / "nerf"), read_dataset(tmp_path / "colmap")
    _same_views(nerf, capture)
    pts = strands.points.astype(np.float64)
    assert check_strands_in_views(pts, capture.train) > 0.95
    height = np.ptp(pts[:, 1])
    for moved in (pts * 100.0, pts + [0.0, height, 0.0]):  # centimetres; a head's height off
        with pytest.raises(DatasetError, match="not in the same frame"):
            check_strands_in_views(moved, capture.train)


# --- bad input --------------------------------------------------------------------------------------


def _text_model(folder, cameras: str, images: str):
    sparse = folder / "sparse" / "0"
    sparse.mkdir(parents=True)
    (folder / "images").mkdir()
    (sparse / "cameras.txt").write_text("# Camera list\n" + cameras)
    (sparse / "images.txt").write_text("# Image list\n" + images)
    return sparse


@pytest.mark.parametrize("model", ["OPENCV 64 64 50 50 32 32 0.1 0 0 0", "SIMPLE_RADIAL 64 64 50 32 32 0.1"])
def test_distorted_camera_is_refused(tmp_path, model):
    _text_model(tmp_path, f"1 {model}\n", "1 1 0 0 0 0 0 3 1 a.png\n\n")
    with pytest.raises(ColmapError, match="needs undistortion.*image_undistorter"):
        read_dataset(tmp_path)


@pycolmap_needed
def test_distorted_binary_camera_is_refused(tmp_path):
    import pycolmap

    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="OPENCV", width=64, height=64, camera_id=1,
                                                    params=[50, 50, 32, 32, 0.1, 0, 0, 0]))
    rec.add_image_with_trivial_frame(pycolmap.Image(name="a.png", camera_id=1, image_id=1),
                                     pycolmap.Rigid3d(pycolmap.Rotation3d(np.eye(3)), np.array([0, 0, 3.0])))
    rec.write(str(tmp_path))
    with pytest.raises(ColmapError, match="OPENCV model, which needs undistortion"):
        read_model(tmp_path)


def test_model_without_images(tmp_path):
    _text_model(tmp_path, "1 PINHOLE 64 64 50 50 32 32\n", "")
    with pytest.raises(ColmapError, match="no registered images"):
        read_dataset(tmp_path)


def test_malformed_models(tmp_path):
    sparse = _text_model(tmp_path, "1 PINHOLE 64 64 50 50 32 32\n", "1 1 0 0 0 0 0 3 7 a.png\n\n")
    with pytest.raises(ColmapError, match="camera 7, which is not in the model"):
        read_model(sparse)
    (sparse / "images.txt").write_text("1 1 0 0 zero 0 0 3 1 a.png\n\n")
    with pytest.raises(ColmapError, match="images.txt:1: malformed image line"):
        read_model(sparse)
    for f in sparse.iterdir():
        f.unlink()
    (sparse / "cameras.bin").write_bytes(struct.pack("<QiiQQ", 1, 5, 1, 64, 64))  # id 5, PINHOLE, no params
    (sparse / "images.bin").write_bytes(struct.pack("<Q", 0))
    with pytest.raises(ColmapError, match="cameras.bin: truncated at byte 32"):
        read_model(sparse)


def test_folder_without_a_dataset(tmp_path):
    with pytest.raises(DatasetError, match="transforms_train.json .* or a COLMAP model"):
        read_dataset(tmp_path)
    _text_model(tmp_path, "1 PINHOLE 64 64 50 50 32 32\n", "1 1 0 0 0 0 0 3 1 a.png\n\n")
    shutil.rmtree(tmp_path / "images")
    with pytest.raises(DatasetError, match="images folder images/ .* is missing"):
        read_dataset(tmp_path)


@pycolmap_needed
def test_missing_and_mismatched_files(scene, tmp_path):
    from PIL import Image

    root, _ = scene
    nerf_to_colmap(root / "nerf", tmp_path)
    (tmp_path / "masks" / "r_003.png").unlink()
    with pytest.raises(DatasetError, match="hair mask of r_003.png is missing"):
        read_dataset(tmp_path)
    Image.new("L", (32, 64)).save(tmp_path / "masks" / "r_003.png")
    with pytest.raises(DatasetError, match="r_003.png is 32 x 64 pixels, its image r_003.png is 64 x 64"):
        read_dataset(tmp_path)
    Image.new("L", (64, 64)).save(tmp_path / "masks" / "r_003.png")
    (tmp_path / "images" / "r_005.png").unlink()
    with pytest.raises(DatasetError, match="r_005.png is missing"):
        read_dataset(tmp_path)
    Image.new("RGB", (32, 64)).save(tmp_path / "images" / "r_005.png")
    with pytest.raises(DatasetError, match="not a resized copy"):
        read_dataset(tmp_path)


@pycolmap_needed
def test_capture_without_masks_warns(scene, tmp_path):
    root, _ = scene
    nerf_to_colmap(root / "nerf", tmp_path)
    shutil.rmtree(tmp_path / "masks")
    with pytest.warns(UserWarning, match="12 of 12 images have no hair mask"):
        ds = read_dataset(tmp_path)
    assert all(v.image[..., 3].min() == 1.0 for v in ds.train)



def _thin(views: list[View], factor: float = 0.3) -> list[View]:
    """``views`` with their alpha scaled by ``factor``: the masks of sub-pixel, mostly translucent hair
    (a Cycles render of 800 wavy strands at 128 px has 3 % of its covered pixels more than half covered)."""
    return [View(v.camera, np.concatenate([v.image[..., :3], v.image[..., 3:] * factor], -1), v.name)
            for v in views]


def test_thin_masks_count_every_covered_pixel(scene):
    """Hair thinner than a pixel leaves masks below one half: the check counts any coverage there, so
    strands where the hair is pass and strands elsewhere are still refused, with the masks' figures."""
    root, strands = scene
    views = _thin(read_dataset(root / "nerf").train)
    pts = strands.points.astype(np.float64)
    covered, solid = solid_share(views)
    assert solid == 0 and 0.05 < covered < 0.9
    assert fraction_in_masks(pts, views).max() == 0  # no pixel reaches one half
    assert check_strands_in_views(pts, views) > 0.9
    for moved in (pts + [0.0, 5.0, 0.0], pts * 100.0):
        with pytest.raises(DatasetError, match=r"the masks are thin \(\d+% of the pixels covered, 0% of those "
                                               r"more than half\); .*--thickness.* not in the same frame"):
            check_strands_in_views(moved, views)


def test_cli_trains_on_thin_masks_and_names_the_frame_when_cameras_moved(scene, tmp_path, capsys):
    """``cgh train`` on a dataset of mostly translucent masks trains; the same dataset with its
    (opaque-masked) cameras moved away from the hair is refused as another frame."""
    root, strands = scene
    ds = read_dataset(root / "nerf")
    write_dataset(tmp_path / "thin", Dataset(_thin(ds.train), _thin(ds.test), ds.meta))
    away = [View(replace(v.camera, world_to_camera=v.camera.world_to_camera @ _shift([0.0, 5.0, 0.0])), v.image,
                 v.name) for v in ds.train + ds.test]
    write_dataset(tmp_path / "away", Dataset(away[:len(ds.train)], away[len(ds.train):], ds.meta))
    save_strands(strands, tmp_path / "s.npz")
    common = ["--strands", str(tmp_path / "s.npz"), "-o", str(tmp_path / "h.cgh"), "--iters", "2", "--n-cards", "8",
              "--groups", "2", "--points", "6", "--no-progress", "--threads", "1"]
    assert main(["train", str(tmp_path / "thin"), *common]) == 0
    assert (tmp_path / "h.cgh").is_file()
    capsys.readouterr()
    assert main(["train", str(tmp_path / "away"), *common]) == 2
    err = capsys.readouterr().err.strip()
    assert "not in the same frame" in err and "masks are thin" not in err and "\n" not in err


def _shift(offset) -> np.ndarray:
    """A world transform moving points by ``-offset``: composed into a camera, it sees the scene moved."""
    m = np.eye(4)
    m[:3, 3] = -np.asarray(offset)
    return m

@pycolmap_needed
def test_cli_reads_a_capture_and_refuses_strands_elsewhere(scene, tmp_path, capsys):
    root, strands = scene
    nerf_to_colmap(root / "nerf", tmp_path / "cap", text=True)
    save_strands(strands, tmp_path / "s.npz")
    out = tmp_path / "h.cgh"
    common = ["-o", str(out), "--iters", "2", "--n-cards", "8", "--groups", "2", "--points", "6",
              "--no-progress", "--threads", "1"]
    assert main(["train", str(tmp_path / "cap"), "--strands", str(tmp_path / "s.npz"), *common]) == 0
    assert "COLMAP layout (sparse model sparse/0/ .txt, images images/, masks masks/)" in capsys.readouterr().out
    assert main(["eval", str(out), str(tmp_path / "cap"), "--no-lpips", "--threads", "1"]) == 0
    assert "COLMAP layout" in capsys.readouterr().out
    moved = strands.__class__(strands.points * 100, strands.offsets)
    save_strands(moved, tmp_path / "cm.npz")
    assert main(["train", str(tmp_path / "cap"), "--strands", str(tmp_path / "cm.npz"), *common]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cgh train: error: only ") and "not in the same frame" in err and "\n" not in err


@pytest.mark.parametrize("case,message", [
    ("distorted", "uses the OPENCV model, which needs undistortion"),
    ("no images", "the COLMAP model has no registered images"),
    ("missing image", "a.png is missing (image 'a.png' of the COLMAP model"),
    ("mask size", "masks must match their images"),
])
def test_bad_captures_are_one_line_cli_errors(tmp_path, strands, case, message, capsys):
    from PIL import Image

    cameras = "1 OPENCV 64 64 50 50 32 32 0.1 0 0 0\n" if case == "distorted" else "1 PINHOLE 64 64 50 50 32 32\n"
    _text_model(tmp_path / "cap", cameras, "" if case == "no images" else "1 1 0 0 0 0 0 3 1 a.png\n\n")
    if case == "mask size":
        Image.new("RGB", (64, 64)).save(tmp_path / "cap" / "images" / "a.png")
        (tmp_path / "cap" / "masks").mkdir()
        Image.new("L", (48, 64)).save(tmp_path / "cap" / "masks" / "a.png")
    save_strands(strands, tmp_path / "s.npz")
    assert main(["train", str(tmp_path / "cap"), "--strands", str(tmp_path / "s.npz"), "-o", str(tmp_path / "h.cgh"),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cgh train: error: ") and message in err and err.count("\n") == 1, err
