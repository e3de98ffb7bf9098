"""Where ``python -m training.bench`` keeps its cards and datasets: the user's cache, not the repository."""

from __future__ import annotations

from pathlib import Path

from training import bench


def test_work_folder_is_the_user_cache_unless_moved(monkeypatch, tmp_path):
    monkeypatch.delenv("CGH_BENCH_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert bench.cache_dir() == tmp_path / "xdg" / "cghair" / "bench"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert bench.cache_dir() == Path.home() / ".cache" / "cghair" / "bench"
    monkeypatch.setenv("CGH_BENCH_DIR", str(tmp_path / "moved"))
    assert bench.cache_dir() == tmp_path / "moved"


def test_an_unusable_work_folder_is_one_line_and_exit_2(tmp_path, capsys):
    (tmp_path / "file").write_text("not a folder")
    code = bench.main(["--strands", "any.npz", "--backend", "reference", "--work", str(tmp_path / "file" / "w")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "cannot create the work folder" in err and "give another with --work" in err
