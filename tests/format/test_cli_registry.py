"""Where `cgh` finds its verbs: the format's own, and the tables the packages above it register by entry
point; verb modules stay light, so `cgh info` loads no torch, GL or scikit-learn."""

import subprocess
import sys
from importlib.metadata import entry_points

import pytest

import cghair_format as cgh
from cghair_format.cli import main
from cghair_format.cli.registry import VERB_GROUP, VERBS, registered, verbs
from cghair_format.examples import example_asset

EVERY_VERB = {"info", "validate", "encode", "synth", "convert", "export", "cards", "render-dataset", "train", "eval",
              "ablation", "reconstruct", "fit-strand-prior", "eval-strands", "view", "render", "bench-viewer", "demo",
              "animate", "batch"}
REINSTALL = "the package metadata is stale: pip install --no-deps --no-build-isolation -e ."


def test_each_package_registers_its_own_verbs():
    tables = {entry.name: entry for entry in entry_points(group=VERB_GROUP)}
    assert set(tables) == {"batch", "training", "viewer"}, REINSTALL
    assert set(verbs()) == EVERY_VERB
    owners = {name: "cghair_format" for name in VERBS}
    for package, entry in tables.items():
        owners.update({name: package for name in entry.load()})
    for name, verb in verbs().items():
        assert verb.module.split(".")[0] == owners[name], f"cgh {name} lives outside the package that registers it"


def test_encode_views_is_a_step_the_training_package_registers():
    from training.cli_encode_views import negligible_from_views

    assert registered("cgh.negligible", "views") is negligible_from_views, REINSTALL
    assert registered("cgh.negligible", "nothing") is None


def test_info_loads_no_heavy_package(tmp_path):
    """Building the parser imports every verb module: none may import torch, GL or scikit-learn at its top."""
    path = tmp_path / "a.cgh"
    cgh.write(example_asset(0, strands=8), path)
    code = ("import sys; from cghair_format.cli import main; assert main(['info', sys.argv[1]]) == 0; "
            "print([m for m in ('torch', 'moderngl', 'glfw', 'sklearn', 'training.train', 'viewer.renderer') "
            "if m in sys.modules])")
    res = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1] == "[]"


def test_a_verb_whose_module_cannot_load_is_unavailable_in_one_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "training.cli_eval", None)  # as if its package's imports failed
    assert main(["eval", "a.cgh", "dataset", "--backend", "native"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cgh eval: unavailable: ") and len(err.strip().splitlines()) == 1


def test_a_package_that_cannot_load_takes_only_its_verbs(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "viewer.verbs", None)
    assert {"train", "info"} <= set(verbs()) and "view" not in verbs()
    with pytest.raises(SystemExit) as exc:
        main(["view", "a.cgh"])
    assert exc.value.code == 2 and "invalid choice: 'view'" in capsys.readouterr().err


def test_an_unknown_verb_gives_usage_not_traceback():
    r = subprocess.run([sys.executable, "-m", "cghair_format", "nosuch"], capture_output=True, text=True)
    assert r.returncode == 2 and "invalid choice: 'nosuch'" in r.stderr and "Traceback" not in r.stderr


def test_encode_views_without_the_step_names_the_extra(tmp_path, monkeypatch, capsys):
    source = tmp_path / "a.cgh"
    cgh.write(example_asset(0, strands=8), source)
    monkeypatch.setattr("cghair_format.cli.encode.registered", lambda group, name: None)
    assert main(["encode", str(source), "-o", str(tmp_path / "b.cgh"), "--views", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "cgh encode --views needs the optional package 'training'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "b.cgh").exists()
