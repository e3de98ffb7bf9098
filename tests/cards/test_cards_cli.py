"""``cgh cards``: the command line of the card builder."""

import numpy as np
import pytest
from cards_helpers import synth
from hairdata import hair_path

from cghair_format import read
from cghair_format.cli import main
from cghair_format.exchange import save_strands


@pytest.fixture(scope="module")
def strand_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("cards") / "wavy.npz"
    save_strands(synth("wavy", 120, 20), path)
    return path


def test_build_write_and_report(strand_file, tmp_path, capsys):
    out = tmp_path / "out.cgh"
    debug = tmp_path / "debug"
    code = main(["cards", str(strand_file), "-o", str(out), "--cards", "12", "--groups", "3", "--segments", "8",
                 "--points", "24", "--sh-degree", "1", "--debug-dir", str(debug), "--no-progress",
                 "--attribution", "test hair"])
    text = capsys.readouterr().out
    assert code == 0
    assert "12 cards of 8 segments, 3 groups" in text
    assert "point error before quantization" in text and "point error after quantization (compact)" in text
    # the file stores strands card by card; the error is measured against each strand's own input
    after = [ln for ln in text.splitlines() if "after quantization" in ln][0]
    assert float(after.split("(")[-1].rstrip(")")) <= 2e-4 + 1e-6  # max error / bbox diagonal
    for stage in ("cluster", "guide", "normals", "uv", "textures"):
        assert stage in text
    asset = read(out)
    assert asset.cards.count == 12 and asset.appearance.n_groups == 3 and asset.uvd.shape == (120, 24, 3)
    assert asset.appearance.sh_degree == 1 and asset.attribution == "test hair"
    assert (debug / "textures.png").exists() and (debug / "cards.obj").exists()
    assert len(list((debug / "textures").glob("card_*.png"))) == 12
    assert main(["info", str(out)]) == 0
    info = capsys.readouterr().out
    assert "12 cards" in info and "3 groups" in info


def test_real_model_with_default_profile(tmp_path, capsys):
    src = hair_path("Curly_100.ply")
    out = tmp_path / "curly.cgh"
    assert main(["cards", str(src), "-o", str(out), "--cards", "10", "--groups", "2", "--no-progress",
                 "--profile", "lossless"]) == 0
    text = capsys.readouterr().out
    before = [ln for ln in text.splitlines() if "before quantization" in ln][0]
    after = [ln for ln in text.splitlines() if "after quantization" in ln][0]
    assert before.split("max")[1] == after.split("max")[1]  # lossless: nothing changes


@pytest.mark.parametrize("args, message", [
    (["missing.hair"], "No such file"),
    (["{bad}"], "truncated"),
])
def test_bad_inputs_give_clear_errors(args, message, tmp_path, capsys):
    bad = tmp_path / "bad.hair"
    bad.write_bytes(b"not a hair file at all")
    argv = ["cards"] + [a.replace("{bad}", str(bad)) for a in args] + ["-o", str(tmp_path / "o.cgh"), "--no-progress"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "o.cgh").exists()


def test_debug_dir_must_be_a_folder(strand_file, tmp_path, capsys):
    clash = tmp_path / "file.txt"
    clash.write_text("x")
    argv = ["cards", str(strand_file), "-o", str(tmp_path / "o.cgh"), "--debug-dir", str(clash), "--no-progress"]
    assert main(argv) == 2
    assert "not a folder" in capsys.readouterr().err


def test_missing_output_folder(strand_file, tmp_path, capsys):
    assert main(["cards", str(strand_file), "-o", str(tmp_path / "nope" / "o.cgh"), "--no-progress"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_output_must_be_cgh(strand_file, tmp_path, capsys):
    assert main(["cards", str(strand_file), "-o", str(tmp_path / "out.ply"), "--no-progress"]) == 2
    assert ".cgh" in capsys.readouterr().err


@pytest.mark.parametrize("option", [["--cards", "0"], ["--points", "3"], ["--groups", "x"], ["--sh-degree", "5"]])
def test_bad_options_are_usage_errors(strand_file, tmp_path, option, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["cards", str(strand_file), "-o", str(tmp_path / "o.cgh")] + option)
    assert exc.value.code == 2
    assert "usage" in capsys.readouterr().err


def test_debug_obj_matches_the_cards(strand_file, tmp_path, capsys):
    out = tmp_path / "o.cgh"
    assert main(["cards", str(strand_file), "-o", str(out), "--cards", "5", "--groups", "2", "--segments", "6",
                 "--points", "16", "--debug-dir", str(tmp_path / "d"), "--no-progress"]) == 0
    lines = (tmp_path / "d" / "cards.obj").read_text().splitlines()
    verts = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    faces = [ln for ln in lines if ln.startswith("f ")]
    assert len(verts) == 5 * 2 * 7 and len(faces) == 5 * 2 * 6
    assert sum(ln.startswith("o card_") for ln in lines) == 5
    from PIL import Image

    atlas = np.asarray(Image.open(tmp_path / "d" / "textures.png"))
    assert atlas.ndim == 3 and atlas.shape[2] == 3 and atlas.max() > 200  # strands drawn white
