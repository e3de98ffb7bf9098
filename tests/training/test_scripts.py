"""The ablation and speed scripts run end to end on a tiny scene and print their tables; the ablation's
sweeps, its row-by-row record and resume, and its refusals of bad arguments."""

from __future__ import annotations

import json

import pytest

import training.train
from cghair_format.cli import main as cgh_main
from training import ablation, bench

# a tiny run: 4 views of 16 x 16 (LPIPS needs 31: test_export_failure_keeps_the_row uses 32), 6 cards
TINY = ["--iters", "4", "--views", "4", "--res", "16", "--engine", "splat", "--n-cards", "6", "--points", "6",
        "--threads", "1"]
REAL_TRAIN = training.train.train


def _counting_train(monkeypatch, fail_at: int | None = None) -> list[str]:
    """Count the trainer's calls (the variant or value each trains); the ``fail_at``-th call raises
    before training, as a run stopped there would."""
    calls: list[str] = []

    def train(*args, config, **kwargs):
        calls.append(f"{config.variant} K={config.codebook_size}")
        if len(calls) == fail_at:
            raise training.train.TrainError("stopped for the test")
        return REAL_TRAIN(*args, config=config, **kwargs)

    monkeypatch.setattr(training.train, "train", train)
    return calls


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
    # each row keeps its training curve (the mean PSNR of each logged window), plotted and summed up
    assert [it for it, _ in rows["latents"]["history"]] == [1, 2, 3, 4]
    assert rows["latents"]["history"][-1][1] == rows["latents"]["train_psnr"]
    assert (tmp_path / "w" / "ablation_curves.png").is_file()
    rise = ablation.late_rise(rows["latents"]["history"])
    assert f"| {rows['latents']['train_psnr']:.2f} ({rise:+.2f}) |" in out
    assert "ablation on splat-rendered held-out views (4 views of 16 px)" in out
    # from a given dataset: its own views, whatever --views and --res say, and the record does not claim them
    given = tmp_path / "w" / "dataset_splat"
    assert ablation.main(["--strands", str(strands_file), "--work", str(tmp_path / "w2"), "--iters", "1",
                          "--dataset", str(given), "--variants", "latents", "--n-cards", "6", "--points", "6",
                          "--threads", "1"]) == 0
    assert f"ablation on the held-out views of {given}" in capsys.readouterr().out
    record = json.loads((tmp_path / "w2" / "ablation.json").read_text())
    assert record["dataset"] == str(given) and not {"views", "res", "engine"} & set(record)


def test_late_rise_reads_the_last_tenth_of_the_run():
    rising = [[i * 150, 30 + i / 10] for i in range(1, 21)]  # 20 windows of 150 iterations, +0.1 dB each
    assert ablation.late_rise(rising) == pytest.approx(0.2)  # 2,700 -> 3,000
    assert ablation.late_rise([[150 * i, 33.0] for i in range(1, 21)]) == 0
    assert ablation.late_rise([[3000, 33.0]]) is None and ablation.late_rise(None) is None


@pytest.mark.parametrize("script", [ablation, bench])
def test_scripts_refuse_a_device_this_torch_cannot_use(tmp_path, strands_file, script, capsys):
    assert script.main(["--strands", str(strands_file), "--work", str(tmp_path / "w"), "--iters", "2",
                        "--views", "2", "--res", "8", "--engine", "splat", "--n-cards", "4", "--points", "4",
                        "--device", "gpu9"]) == 2
    assert "unknown torch device 'gpu9'" in capsys.readouterr().err


def test_ablation_rejects_unknown_variant(tmp_path, strands_file, capsys):
    assert ablation.main(["--strands", str(strands_file), "--variants", "latents,bogus"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown variants ['bogus']" in err


def test_sweeps_write_rows_and_plots(tmp_path, strands_file, capsys):
    work = tmp_path / "w"
    assert ablation.main(["--strands", str(strands_file), "--work", str(work), *TINY,
                          "--sweep", "K=2,3", "--sweep", "N_T=1,6"]) == 0
    out = capsys.readouterr().out
    assert "K sweep of the latents variant" in out and "| 3 |" in out and "paper columns: its own sweep" in out
    k = json.loads((work / "sweep_K.json").read_text())
    assert k["param"] == "K" and k["iterations"] == 4 and [r["value"] for r in k["rows"]] == [2, 3]
    small, large = k["rows"]
    # one more codebook entry per group and one more logit per strand: more appearance, and a file
    assert large["appearance_bytes"] > small["appearance_bytes"] and small["file_bytes"] > 0
    assert all(r["groups"] == small["groups"] for r in k["rows"]) and "file_psnr" in large
    n_t = json.loads((work / "sweep_N_T.json").read_text())
    assert [r["groups"] for r in n_t["rows"]] == [1, 6]  # N_T = --n-cards: one group per card
    assert (work / "sweep_K.png").is_file() and (work / "sweep_N_T.png").is_file()
    assert not (work / "ablation.json").exists()  # --sweep runs the sweeps instead of the variants


def test_rerun_resumes_after_the_last_finished_row(tmp_path, strands_file, monkeypatch, capsys):
    """Rows are written as they finish: a run stopped at its second variant keeps the first, and the
    rerun trains only what is missing."""
    argv = ["--strands", str(strands_file), "--work", str(tmp_path / "w"), *TINY, "--variants", "latents,unique"]
    calls = _counting_train(monkeypatch, fail_at=2)
    assert ablation.main(argv) == 2
    assert "stopped for the test" in capsys.readouterr().err
    rows = json.loads((tmp_path / "w" / "ablation.json").read_text())["rows"]
    assert [r["variant"] for r in rows] == ["latents"]
    calls = _counting_train(monkeypatch)
    assert ablation.main(argv) == 0
    assert calls == ["unique K=10"]
    assert "rows already there, not trained again: variant latents" in capsys.readouterr().err
    assert [r["variant"] for r in json.loads((tmp_path / "w" / "ablation.json").read_text())["rows"]] == \
        ["latents", "unique"]
    calls.clear()
    sweep = [*argv[:-2], "--sweep", "K=2,3"]
    assert ablation.main([*argv[:-2], "--sweep", "K=3"]) == 0 and calls == ["latents K=3"]
    capsys.readouterr()
    assert ablation.main([*argv[:-2], "--sweep", "K=2"]) == 0 and calls == ["latents K=3", "latents K=2"]
    captured = capsys.readouterr()
    assert "rows already there, not trained again: value 3" in captured.err
    assert "| 3 |" in captured.out and "| 2 |" in captured.out  # the folder's rows, earlier calls' included
    # other settings in the same folder: refused, not mixed
    assert ablation.main([*sweep[:sweep.index("--iters") + 1], "5", *sweep[sweep.index("--iters") + 2:]]) == 2
    assert "holds rows of another run (iterations 4 there, 5 now)" in capsys.readouterr().err


def test_runs_side_by_side_keep_each_others_rows(tmp_path, strands_file, monkeypatch):
    """Two runs in one folder with other variants: the one that finishes last keeps the other's row."""
    base = ["--strands", str(strands_file), "--work", str(tmp_path / "w"), *TINY]
    beside: list[int] = []

    def train(*args, config, **kwargs):
        if config.variant == "latents":  # the run beside finishes unique while this one trains latents
            beside.append(ablation.main([*base, "--variants", "unique"]))
        return REAL_TRAIN(*args, config=config, **kwargs)

    monkeypatch.setattr(training.train, "train", train)
    assert ablation.main([*base, "--variants", "latents"]) == 0 and beside == [0]
    rows = json.loads((tmp_path / "w" / "ablation.json").read_text())["rows"]
    assert [r["variant"] for r in rows] == ["unique", "latents"]
    assert rows[1]["ratio_vs_unique"] > 1  # the ratio is taken against the other run's row


def test_a_variant_stopped_midway_resumes_from_its_checkpoint(tmp_path, strands_file, monkeypatch, capsys):
    """A run stopped inside a variant (a session's end) keeps that variant's checkpoint; the rerun
    continues it from there rather than from the start, and never from another run's checkpoint."""
    argv = ["--strands", str(strands_file), "--work", str(tmp_path / "w"), *TINY, "--variants", "latents"]
    done: list[int] = []

    def stopped(*args, config, **kwargs):  # trains 2 of the 4 iterations, then the session ends
        REAL_TRAIN(*args, config=config, stop_at=2, **kwargs)
        raise training.train.TrainError("stopped for the test")

    monkeypatch.setattr(training.train, "train", stopped)
    assert ablation.main(argv) == 2
    ckpt = tmp_path / "w" / "latents.ckpt.pt"
    cfg = ablation.scaled_config("latents", 4, n_cards=6, points_per_strand=6)
    assert ablation._resumable(ckpt, cfg) == 2
    assert ablation._resumable(ckpt, ablation.scaled_config("latents", 4, n_cards=6, points_per_strand=5)) is None

    def counting(*args, config, **kwargs):
        result = REAL_TRAIN(*args, config=config, **kwargs)
        done.append(result.iterations_run)
        return result

    monkeypatch.setattr(training.train, "train", counting)
    capsys.readouterr()
    assert ablation.main(argv) == 0
    assert done == [2]  # the two iterations left, not four
    assert "latents: resuming" in capsys.readouterr().err
    row = json.loads((tmp_path / "w" / "ablation.json").read_text())["rows"][0]
    assert row["variant"] == "latents" and row["iterations"] == 4 and "file_psnr" in row


def test_a_damaged_row_file_is_refused_before_the_dataset(tmp_path, strands_file, capsys):
    work = tmp_path / "w"
    work.mkdir()
    (work / "ablation.json").write_text('{"rows": [')
    assert ablation.main(["--strands", str(strands_file), "--work", str(work), *TINY]) == 2
    err = capsys.readouterr().err
    assert "ablation.json is not valid JSON" in err and err.count("\n") == 1
    assert not (work / "dataset_splat").exists()


def test_export_failure_keeps_the_row(tmp_path, strands_file, monkeypatch, capsys):
    def choose_export(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr(training.train, "choose_export", choose_export)
    argv = ["--strands", str(strands_file), "--work", str(tmp_path / "w"), *TINY, "--res", "32",
            "--variants", "latents"]
    assert ablation.main(argv) == 0
    assert "the row keeps the model's figures" in capsys.readouterr().err
    row = json.loads((tmp_path / "w" / "ablation.json").read_text())["rows"][0]
    assert row["export_error"] == "OSError: No space left on device" and "file_bytes" not in row
    assert row["psnr"] > 0 and row["lpips"] is not None and row["lpips"] >= 0


@pytest.mark.parametrize(("sweep", "message"), [
    ("X=1,2", "give KEY=V1,V2,... with KEY one of K, D, N_T"),
    ("K=2,a", "values must be integers"),
    ("K", "give KEY=V1,V2,..."),
    ("K=2,2", "a value is repeated"),
    ("K=300", "--sweep K=300: codebook_size must be <= 256"),
    ("D=0", "--sweep D=0: latent_dim must be a positive integer"),
    ("N_T=7", "--sweep N_T=7: more card groups than cards (6); give --n-cards 7 or more"),
])
def test_bad_sweeps_are_refused_in_one_line(tmp_path, strands_file, capsys, sweep, message):
    work = tmp_path / "w"
    for main, prefix in ((ablation.main, "ablation: error: "), (cgh_main, "cgh ablation: error: ")):
        argv = ["--strands", str(strands_file), "--work", str(work), *TINY, "--sweep", sweep]
        assert main(argv if main is ablation.main else ["ablation", *argv]) == 2
        err = capsys.readouterr().err
        assert err.startswith(prefix) and message in err and err.count("\n") == 1
    assert not work.exists()  # refused before the dataset


def test_missing_strands_are_refused_before_the_work_folder(tmp_path, capsys):
    assert cgh_main(["ablation", "--strands", str(tmp_path / "none.tfx"), "--work", str(tmp_path / "w"), *TINY]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cgh ablation: error: No such file") and err.count("\n") == 1
    assert not (tmp_path / "w").exists()


def test_a_missing_dataset_is_refused_not_rendered_into(tmp_path, strands_file, capsys):
    missing = tmp_path / "no_such_dataset"
    assert cgh_main(["ablation", "--strands", str(strands_file), "--work", str(tmp_path / "w"), *TINY,
                     "--dataset", str(missing)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cgh ablation: error: ") and err.count("\n") == 1
    assert not missing.exists()


def test_cgh_ablation_runs_the_sweep(tmp_path, strands_file, capsys):
    assert cgh_main(["ablation", "--strands", str(strands_file), "--work", str(tmp_path / "w"), *TINY,
                     "--sweep", "d=4"]) == 0
    assert "D sweep of the latents variant (latent_dim)" in capsys.readouterr().out
    assert json.loads((tmp_path / "w" / "sweep_D.json").read_text())["rows"][0]["value"] == 4


def test_bench_prints_a_breakdown(tmp_path, strands_file, capsys):
    assert bench.main(["--strands", str(strands_file), "--work", str(tmp_path / "b"), "--iters", "3",
                       "--views", "4", "--res", "16", "--points", "6", "--n-cards", "6", "--threads", "1"]) == 0
    out = capsys.readouterr().out
    assert "it/s" in out and "render" in out and "backward" in out and "held-out: PSNR" in out
