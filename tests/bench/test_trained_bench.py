"""The trained paper-scale file (``make paper-trained``) on its Cycles dataset's held-out views:
PSNR, SSIM and LPIPS of the file as decoded, its appearance chunks against the free-SH size, and how it
was trained. Skips, saying how to make them, when the file or the dataset is absent.
"""

from __future__ import annotations

import pytest

from .paper_scale import PAPER_DATA, trained_paper_scale_asset

pytestmark = pytest.mark.bench
pytest.importorskip("torch", reason="evaluating the trained file needs torch (pip install 'cghair[training]')")

APPEARANCE_CHUNKS = ("LOGT", "CBKS", "MLPW")


def test_trained_paper_scale(benchmark):
    from cghair_format.container import read_table
    from training.evaluate import evaluate

    from .paper_scale import TRAINED

    asset, appearance = trained_paper_scale_asset()
    dataset = PAPER_DATA / "cycles"
    if not (dataset / "transforms_test.json").is_file():
        pytest.skip(f"no Cycles dataset at {dataset}: `make paper-trained` renders it")
    result = benchmark.pedantic(lambda: evaluate(TRAINED, dataset), rounds=1, iterations=1)
    chunks = {c.type: c.stored for c in read_table(TRAINED.read_bytes())[1]}
    app_bytes = sum(chunks.get(t, 0) for t in APPEARANCE_CHUNKS)
    free_sh = asset.n_gaussians * (asset.appearance.sh_degree + 1) ** 2 * 3 * 4  # float32 SH per Gaussian
    training = asset.metadata.get("training", {})
    row = {"file": appearance, "views": len(result.per_view), "PSNR dB": round(result.psnr, 2),
           "SSIM": round(result.ssim, 4), "LPIPS": None if result.lpips is None else round(result.lpips, 4),
           "bytes": TRAINED.stat().st_size, "appearance bytes": app_bytes,
           "free SH / appearance": round(free_sh / app_bytes),
           "iterations": (training.get("final") or {}).get("iteration"),
           "training s": training.get("seconds_total"), "backend": training.get("backend")}
    print(f"\ntrained paper-scale file: {row}")
    benchmark.extra_info.update({"rows": [row]})
