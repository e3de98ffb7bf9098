"""`cgh demo`, the main job end to end, on a tiny configuration (the viewer's picture needs OpenGL 4.3;
without it the demo says so and the rest stands)."""

import pytest

import cghair_format as cgh
from cghair_format.cli import main


@pytest.mark.slow
def test_demo_runs_the_main_job(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--strands", "60", "--iters", "4", "--views", "4", "--res", "16"]) == 0
    text = capsys.readouterr().out
    assert "demo finished" in text and ("wrote" in text.split("== 7.")[1] or "no picture" in text)
    asset = cgh.read(out / "hair.cgh")
    assert asset.n_strands == 60 and (out / "hair_3dgs.ply").stat().st_size > 0
    assert (out / "dataset" / "transforms_train.json").is_file() and (out / "hair.usda").is_file()
