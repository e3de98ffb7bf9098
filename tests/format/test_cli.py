"""`cgh info`, `cgh validate`, `cgh encode`: output, exit codes and clear errors."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format.cli import main
from cghair_format.examples import example_asset


@pytest.fixture()
def asset_file(tmp_path):
    path = tmp_path / "a.cgh"
    cgh.write(example_asset(1), path)
    return path


def test_info_text_and_json(asset_file, capsys):
    assert main(["info", str(asset_file)]) == 0
    out = capsys.readouterr().out
    assert "bits per Gaussian" in out and "STRD" in out and "profile compact" in out
    assert "base samples every 16 points" in out and "steps stretched up to 1.5x" in out
    assert main(["info", str(asset_file), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["strands"] == 64 and info["profile"] == "compact" and info["quant"]["base_stride"] == 16


def test_info_gives_what_the_mlp_costs(asset_file, capsys):
    """The MLP is a fixed cost whatever the strand count: info counts its values and MLPW's bits each."""
    mlp = cgh.read(asset_file).appearance.mlp
    values = sum(layer.weight.size + layer.bias.size for layer in mlp)
    assert main(["info", str(asset_file), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    stored = next(c["stored_bytes"] for c in info["chunks"] if c["type"] == "MLPW")
    assert info["mlp_weights"] == {"values": values, "stored_bytes": stored, "bits_per_value": 8 * stored / values}
    assert main(["info", str(asset_file)]) == 0
    assert f"MLP         {values:,} weights and biases in {stored:,} bytes, {8 * stored / values:.2f} bits each" \
        in capsys.readouterr().out


def test_info_names_the_writers_strand_coding_choices(capsys):
    """The vectors cover each choice a decoder follows; `cgh info` says which a file took."""
    vectors = Path(__file__).parents[2] / "spec" / "vectors"
    assert main(["info", str(vectors / "synth_cards_neighbour_classes.cgh")]) == 0
    out = capsys.readouterr().out
    assert "every 8 points, guided by the card neighbour's steps, scaled" in out
    assert "3 neighbour token classes" in out
    assert main(["info", str(vectors / "synth_curly_compact.cgh")]) == 0
    out = capsys.readouterr().out
    assert "guided by the most alike earlier strand's steps, level residuals as differences from the most " \
           "alike earlier strand's" in out
    assert main(["info", str(vectors / "synth_children_compact.cgh")]) == 0
    assert "strands interpolated from 2-3 others (CHLD)" in capsys.readouterr().out
    assert main(["info", str(vectors / "minimal_lossless.cgh")]) == 0
    assert "float32 card coordinates (lossless)" in capsys.readouterr().out


def test_validate_exit_codes(asset_file, tmp_path, capsys):
    assert main(["validate", str(asset_file)]) == 0
    bad = tmp_path / "bad.cgh"
    data = bytearray(asset_file.read_bytes())
    data[200] ^= 0x55
    bad.write_bytes(bytes(data))
    assert main(["validate", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "checksum" in err and "byte offset" in err


def test_encode_changes_profile(asset_file, tmp_path, capsys):
    out = tmp_path / "l.cgh"
    assert main(["encode", str(asset_file), "-o", str(out), "--profile", "lossless"]) == 0
    assert cgh.read_info(out)["profile"] == "lossless"


def test_encode_of_a_quantized_file_says_what_its_error_is_measured_against(asset_file, tmp_path, capsys):
    assert main(["encode", str(asset_file), "-o", str(tmp_path / "h.cgh"), "--profile", "high"]) == 0
    out = capsys.readouterr().out
    assert "is a compact file" in out and "0.0002 of the bbox diagonal from the strands it was made from" in out
    lossless = tmp_path / "l.cgh"
    cgh.write(example_asset(1), lossless, "lossless")
    assert main(["encode", str(lossless), "-o", str(tmp_path / "c.cgh")]) == 0
    assert "note:" not in capsys.readouterr().out


@pytest.mark.parametrize("profile", ["high", "compact"])
def test_encode_without_views_keeps_every_opacity_within_the_bound(tmp_path, capsys, profile):
    """Without --views (and so without an opacity budget) no opacity is lowered: each decodes within the
    profile's bound of the input's, the file records none lowered, and info and validate say so."""
    source, out = tmp_path / "src.cgh", tmp_path / "out.cgh"
    asset = example_asset(2, strands=40, points=12)
    asset.opacity = np.random.default_rng(1).uniform(0, 1, asset.opacity.shape).astype(np.float32)
    cgh.write(asset, source, "lossless")
    assert main(["encode", str(source), "-o", str(out), "--profile", profile]) == 0
    assert "opacities" not in capsys.readouterr().out
    prof = cgh.PROFILES[profile]
    own = cgh.encode(asset, profile)[1].in_file_order(asset).opacity  # (the writer's order: it is deterministic)
    assert np.abs(cgh.read(out).opacity - own).max() <= prof.opacity_tolerance + 1e-7
    assert cgh.read_info(out)["opacities"] == {"within": prof.opacity_tolerance, "lowered": None, "budget": None}
    within = f"all within 1/{round(2 * prof.opacity_scale)} of the writer's input"
    assert main(["info", str(out)]) == 0 and f"opacities   {within}" in capsys.readouterr().out
    assert main(["validate", str(out)]) == 0 and f"; opacities: {within}" in capsys.readouterr().out
    assert main(["encode", str(source), "-o", str(out), "--opacity-budget", "0"]) == 2
    assert "--opacity-budget needs --views" in capsys.readouterr().err


def test_info_and_validate_say_how_many_opacities_are_stored_lower(tmp_path, capsys):
    asset = example_asset(3, strands=40, points=12)
    rng = np.random.default_rng(0)
    asset.opacity = rng.uniform(0, 1, asset.opacity.shape).astype(np.float32)
    path = tmp_path / "lowered.cgh"
    report = cgh.write(asset, path, negligible=rng.random(asset.opacity.shape) < 0.8, opacity_budget=0.25)
    assert report.opacity.kept and report.opacity.lowered > 0
    line = f"{report.opacity.lowered:,} of 440 stored lower, down to 0 (budget 0.25); others within 1/15"
    assert main(["info", str(path)]) == 0 and line in capsys.readouterr().out
    assert main(["validate", str(path)]) == 0 and line in capsys.readouterr().out
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["opacities"]["lowered"] == report.opacity.lowered
    assert main(["encode", str(path), "-o", str(tmp_path / "again.cgh")]) == 0
    assert f"stores opacities lower ({line}" in capsys.readouterr().out
    lossless = tmp_path / "lossless.cgh"
    cgh.write(asset, lossless, "lossless")
    assert main(["info", str(lossless)]) == 0 and "opacities   stored exactly" in capsys.readouterr().out


def test_encode_of_a_file_written_with_a_profile_of_ones_own(tmp_path, capsys):
    """A Profile the caller made (its name unknown to the CLI) is stored in META with its point bound:
    re-encoding that file says what its error is measured against."""
    from dataclasses import replace

    mine = tmp_path / "mine.cgh"
    cgh.write(example_asset(1), mine, replace(cgh.PROFILES["compact"], name="mine", position_tolerance=1e-4))
    assert cgh.read_info(mine)["profile"] == "mine"
    assert main(["encode", str(mine), "-o", str(tmp_path / "c.cgh")]) == 0
    assert "is a mine file, so that error is measured against its decoded points, which already lie up to " \
           "0.0001 of the bbox diagonal" in capsys.readouterr().out


def test_a_profile_the_writer_cannot_follow_is_refused_when_made():
    from dataclasses import replace

    for change in ({"normal_bits": 30}, {"base_strides": (12,)}, {"position_tolerance": float("nan")},
                   {"logit_levels": 0}, {"mlp_step": 0.0}):
        with pytest.raises(ValueError, match="profile 'compact': "):
            replace(cgh.PROFILES["compact"], **change)


def test_encode_keeps_the_strand_order_when_asked(tmp_path, capsys):
    source = tmp_path / "src.cgh"
    asset = example_asset(4, strands=30, cards=4)  # its strands come card by card: shuffle them
    cgh.write(asset.take_strands(np.random.default_rng(0).permutation(30)), source, "lossless")
    assert main(["encode", str(source), "-o", str(tmp_path / "kept.cgh"), "--keep-order"]) == 0
    assert "card by card" not in capsys.readouterr().out
    assert np.array_equal(cgh.read(tmp_path / "kept.cgh").strand_card, cgh.read(source).strand_card)
    assert main(["encode", str(source), "-o", str(tmp_path / "sorted.cgh")]) == 0
    assert "strands stored card by card" in capsys.readouterr().out
    assert np.all(np.diff(cgh.read(tmp_path / "sorted.cgh").strand_card) >= 0)


def test_missing_file_and_not_a_cgh(tmp_path, capsys):
    assert main(["info", str(tmp_path / "nope.cgh")]) == 2
    assert "No such file" in capsys.readouterr().err
    txt = tmp_path / "x.cgh"
    txt.write_text("hello")
    assert main(["validate", str(txt)]) == 1
    assert "not a .cgh file" in capsys.readouterr().err


def test_every_verb_has_help():
    from cghair_format.cli.registry import verbs

    for verb in verbs():
        r = subprocess.run([sys.executable, "-m", "cghair_format", verb, "--help"], capture_output=True, text=True)
        assert r.returncode == 0, f"cgh {verb} --help failed: {r.stderr}"
        assert "usage: cgh" in r.stdout


def test_bad_arguments_give_usage_not_traceback():
    r = subprocess.run([sys.executable, "-m", "cghair_format", "encode", "x.cgh", "--profile", "tiny"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "invalid choice" in r.stderr and "Traceback" not in r.stderr


def test_output_into_a_closed_pipe_is_quiet(asset_file):
    """`cgh info FILE | head -1`: the reader has gone before cgh writes; no traceback."""
    proc = subprocess.Popen([sys.executable, "-m", "cghair_format", "info", str(asset_file)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # closed long before the interpreter has started and read the file
    err = proc.stderr.read()
    assert proc.wait() == 141 and "Traceback" not in err, err


def test_every_verb_takes_a_variable_count_file(tmp_path, capsys):
    """info, validate (with the reference decoder), encode, convert and export on strands of their own
    point counts; .tfx, one count per file, says to resample."""
    from cghair_format.examples import with_point_counts
    from cghair_format.exchange import load_strands

    asset = with_point_counts(example_asset(0, strands=24, points=12), seed=3)
    src = tmp_path / "v.cgh"
    cgh.write(asset, src)
    capsys.readouterr()
    assert main(["info", str(src)]) == 0
    out = capsys.readouterr().out
    assert ".cgh 2.1" in out and f"24 x 2-12 points, {asset.n_gaussians:,} Gaussians" in out
    assert main(["validate", str(src), "--reference"]) == 0
    out = capsys.readouterr().out
    assert "of 2-12 points" in out and "same points on all 24 strands" in out
    assert main(["encode", str(src), "-o", str(tmp_path / "high.cgh"), "--profile", "high"]) == 0
    assert np.array_equal(np.sort(cgh.read(tmp_path / "high.cgh").counts), np.sort(asset.counts))
    assert main(["convert", str(src), str(tmp_path / "v.npz")]) == 0
    assert "2..12 points" in capsys.readouterr().out
    assert np.array_equal(np.sort(load_strands(tmp_path / "v.npz").point_counts), np.sort(asset.counts))
    assert main(["export", str(src), "-o", str(tmp_path / "g.ply")]) == 0
    assert f"{asset.n_gaussians:,} Gaussians" in capsys.readouterr().out
    assert main(["convert", str(src), str(tmp_path / "v.tfx")]) != 0
    err = capsys.readouterr().err
    assert "--points" in err and len(err.strip().splitlines()) == 1
