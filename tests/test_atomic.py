"""Atomic writes (cghair_format/atomic.py): every writer goes through the helper, so that a failure
before the rename (here a KeyboardInterrupt from fsync) leaves the old file and no temporary file, and
new files take the umask's mode; the CLI refuses an unwritable output before its long work."""

import os
import stat

import numpy as np
import pytest

import cghair_format as cgh
from cghair_format import atomic
from cghair_format.cli import main
from cghair_format.examples import example_asset
from cghair_format.exchange import save_strands, write_3dgs_ply
from cghair_format.synth import synthesize


def _write_cgh(path):
    cgh.write(example_asset(11, strands=24, points=12, cards=4, segments=5), path, "compact")


def _write_3dgs(path):
    write_3dgs_ply(cgh.read_with_gaussians(cgh.encode(example_asset(11, strands=24, points=12, cards=4,
                                                                    segments=5), "compact")[0])[1], path)


def _write_png(path):
    from viewer.render_jobs import write_images

    write_images([np.zeros((8, 8, 3), np.float32)], path)


def _strands(ext):
    def write(path):
        save_strands(synthesize("straight", 12, 8, seed=0, multitone=True), path)
    return write


WRITERS = {"out.cgh": _write_cgh, "gauss.ply": _write_3dgs, "image.png": _write_png,
           **{f"strands{ext}": _strands(ext) for ext in (".npz", ".hair", ".tfx", ".data", ".ply", ".usda",
                                                          ".usdc", ".usdz")}}


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


@pytest.mark.parametrize("name", sorted(WRITERS))
def test_writer_is_atomic(name, tmp_path, monkeypatch, umask_022):
    if name.startswith("strands.usd"):
        pytest.importorskip("pxr", reason="usd-core (the usd extra) writes USD")
    path = tmp_path / name
    flushed = []
    real_fsync = os.fsync

    def fsync(fd):
        flushed.append(os.readlink(f"/proc/self/fd/{fd}"))
        real_fsync(fd)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    WRITERS[name](path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644  # 0666 less the umask, as open() makes files
    assert str(tmp_path) in flushed and any(f.startswith(str(tmp_path / f".{name}.")) for f in flushed)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]
    before = path.read_bytes()

    def interrupted(fd):
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "fsync", interrupted)  # after the writer wrote the whole temporary file
    with pytest.raises(KeyboardInterrupt):
        WRITERS[name](path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_umask_077_gives_private_files(tmp_path):
    old = os.umask(0o077)
    try:
        atomic.write_bytes(tmp_path / "a.bin", b"x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.bin").stat().st_mode) == 0o600


def test_an_error_inside_the_writer_leaves_nothing(tmp_path):
    with pytest.raises(ValueError), atomic.atomic_open(tmp_path / "a.bin") as f:
        f.write(b"partial")
        raise ValueError("disk full")
    assert list(tmp_path.iterdir()) == []


WRITING_COMMANDS = [
    ["cards", "{d}/missing.hair", "-o", "{out}.cgh"],
    ["encode", "{d}/missing.cgh", "-o", "{out}.cgh"],
    ["export", "{d}/missing.cgh", "-o", "{out}.usda"],
    ["convert", "{d}/missing.hair", "{out}.ply"],
    ["synth", "-o", "{out}.npz"],
    ["render", "{d}/missing.cgh", "-o", "{out}.png"],
    ["train", "{d}/missing_dataset", "--strands", "{d}/missing.hair", "-o", "{out}.cgh"],
    ["render-dataset", "{d}/missing.hair", "-o", "{out}"],
    ["demo", "-o", "{out}"],
    ["eval", "{d}/missing.cgh", "{d}/missing_dataset", "--out", "{out}"],
    ["cards", "{d}/missing.hair", "-o", "{d}/ok.cgh", "--debug-dir", "{out}"],
]


@pytest.mark.parametrize("command", WRITING_COMMANDS, ids=lambda c: c[0])
def test_cli_refuses_an_output_under_a_file_first(command, tmp_path, capsys):
    """The output check runs before the input is even opened (the inputs here do not exist)."""
    (tmp_path / "file").write_bytes(b"")
    args = [a.format(d=tmp_path, out=tmp_path / "file" / "out") for a in command]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "is a file, not a folder" in err and "Traceback" not in err


def test_cli_refuses_a_folder_as_output_file(tmp_path, capsys):
    (tmp_path / "x.cgh").mkdir()
    assert main(["encode", str(tmp_path / "missing.cgh"), "-o", str(tmp_path / "x.cgh")]) == 2
    assert "is not a folder" not in (err := capsys.readouterr().err) and "it is a folder" in err


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only folder, so this needs a user")
def test_cli_refuses_a_read_only_folder(tmp_path, capsys):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        assert main(["synth", "-o", str(folder / "a.npz")]) == 2
        assert "not writable" in capsys.readouterr().err
    finally:
        folder.chmod(0o755)


def test_read_only_check_as_a_user_would_see_it(tmp_path, monkeypatch):
    """The same refusal with os.access answering as for a user without write permission (for runs as root)."""
    monkeypatch.setattr(atomic.os, "access", lambda path, mode: False)
    with pytest.raises(cgh.CghError, match="not writable"):
        atomic.check_writable(tmp_path / "a.cgh")


def test_train_may_name_a_file_in_folders_it_makes(tmp_path):
    atomic.check_writable(tmp_path / "new" / "deeper" / "hair.cgh", make_parents=True)
    with pytest.raises(cgh.CghError, match="does not exist"):
        atomic.check_writable(tmp_path / "new" / "hair.cgh")
