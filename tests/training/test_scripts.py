"""The ablation and speed scripts run end to end on a tiny scene and print their tables."""

from __future__ import annotations

import json

import pytest

from training import ablation, bench


def test_ablation_table(tmp_path, strands_file, capsys):
    code = ablation.main(["--strands", str(strands_file), "--work", str(tmp_path / "w"), "--iters", "4",
                          "--views", "4", "--res", "16", "--engine", "splat", "--variants", "latents,unique",
                          "--n-cards", "6", "--points", "6", "--threads", "1"])
    assert code == 0
    out = capsys.readouterr().out
    assert "| latents |" in out and "| unique |" in out and "n/a (no .cgh encoding)" in out
    data = json.loads((tmp_path / "w" / "ablation.json").read_text())
    rows = {r["variant"]: r for r in data["rows"]}
    assert rows["unique"]["ratio_vs_unique"] == 1.0 and "file_psnr" in rows["latents"]
    assert (tmp_path / "w" / "ablation.png").is_file() and "paper's table (its data)" in out


@pytest.mark.parametrize("script", [ablation, bench])
def test_scripts_refuse_a_device_this_torch_cannot_use(tmp_path, strands_file, script, capsys):
    assert script.main(["--strands", str(strands_file), "--work", str(tmp_path / "w"), "--iters", "2",
                        "--views", "2", "--res", "8", "--engine", "splat", "--n-cards", "4", "--points", "4",
                        "--device", "gpu9"]) == 2
    assert "unknown torch device 'gpu9'" in capsys.readouterr().err


def test_ablation_rejects_unknown_variant(tmp_path, strands_file):
    with pytest.raises(SystemExit):
        ablation.main(["--strands", str(strands_file), "--variants", "latents,bogus"])


def test_bench_prints_a_breakdown(tmp_path, strands_file, capsys):
    assert bench.main(["--strands", str(strands_file), "--work", str(tmp_path / "b"), "--iters", "3",
                       "--views", "4", "--res", "16", "--points", "6", "--n-cards", "6", "--threads", "1"]) == 0
    out = capsys.readouterr().out
    assert "it/s" in out and "render" in out and "backward" in out and "held-out: PSNR" in out
