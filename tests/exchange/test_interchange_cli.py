"""The cgh synth / convert / export verbs, through cghair_format.cli.main."""

from __future__ import annotations

import numpy as np
import pytest

import cghair_format
from cghair_format.cli import main
from cghair_format.examples import example_asset
from cghair_format.exchange import load_strands
from cghair_format.exchange.ply_3dgs import read_3dgs_ply


def test_synth_convert_chain(tmp_path, capsys):
    a = tmp_path / "a.npz"
    assert main(["synth", "-o", str(a), "--style", "wavy", "--strands", "300", "--points", "24", "--seed", "2"]) == 0
    s = load_strands(a)
    assert s.count == 300 and set(s.point_counts) == {24}
    b = tmp_path / "b.hair"
    assert main(["convert", str(a), str(b), "--points", "12", "--densify", "500", "--seed", "1"]) == 0
    d = load_strands(b)
    assert d.count == 500 and set(d.point_counts) == {12}
    c = tmp_path / "c.ply"
    assert main(["convert", str(b), str(c), "--units", "0.01", "--up", "z", "--method", "bspline",
                 "--points", "20"]) == 0
    assert set(load_strands(c).point_counts) == {20}
    assert "500 -> 500 strands x 20 points" in capsys.readouterr().out


def test_export_verbs(tmp_path):
    asset = example_asset(sh_degree=1)
    cgh = tmp_path / "a.cgh"
    cghair_format.write(asset, cgh)
    usda = tmp_path / "a.usda"
    assert main(["export", str(cgh), "-o", str(usda), "--all"]) == 0
    from pxr import Usd

    stage = Usd.Stage.Open(str(usda))
    assert [p.GetName() for p in stage.GetDefaultPrim().GetChildren()] == ["Strands", "Materials", "Cards", "Gaussians",
                                                                              "GaussianPoints"]
    ply = tmp_path / "g.ply"
    assert main(["export", str(cgh), "-o", str(ply)]) == 0
    g = read_3dgs_ply(ply)
    assert g.count == cghair_format.read(cgh).n_gaussians
    splats = tmp_path / "g.usda"
    assert main(["export", str(ply), "-o", str(splats)]) == 0
    splat_stage = Usd.Stage.Open(str(splats))
    assert splat_stage.GetPrimAtPath("/Hair/Gaussians").GetTypeName() == "ParticleField3DGaussianSplat"
    strands_usd = tmp_path / "s.usdc"
    assert main(["convert", str(cgh), str(tmp_path / "s.npz")]) == 0
    assert main(["export", str(tmp_path / "s.npz"), "-o", str(strands_usd)]) == 0
    np.testing.assert_allclose(load_strands(strands_usd).points, load_strands(tmp_path / "s.npz").points)


@pytest.mark.parametrize("argv,message", [
    (["convert", "{d}/in.npz", "{d}/out.txt"], "cannot write strands as .txt"),
    (["convert", "{d}/missing.hair", "{d}/out.ply"], "No such file"),
    (["convert", "{d}/bad.hair", "{d}/out.ply"], "bad.hair: not a Cem Yuksel"),
    (["export", "{d}/in.npz", "-o", "{d}/x.usda", "--cards"], "exist only in a .cgh asset"),
    (["export", "{d}/in.npz", "-o", "{d}/x.ply"], "3DGS PLY needs Gaussians"),
    (["export", "{d}/in.npz", "-o", "{d}/x.obj"], "export writes"),
    (["export", "{d}/in.npz", "-o", "{d}/x.usda", "--up", "z"], "--up chooses a 3DGS PLY's up axis"),
    (["export", "{d}/in.npz", "-o", "{d}/x.blend", "--scale", "2"], "a .blend is in metres"),
])
def test_cli_errors_are_messages(tmp_path, capsys, argv, message):
    main(["synth", "-o", str(tmp_path / "in.npz"), "--strands", "5", "--points", "4"])
    (tmp_path / "bad.hair").write_bytes(b"NOPE" + bytes(200))
    capsys.readouterr()
    assert main([a.format(d=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_synth_rejects_bad_counts(capsys):
    with pytest.raises(SystemExit) as info:
        main(["synth", "-o", "x.npz", "--points", "1"])
    assert info.value.code == 2
    assert "must be at least 2" in capsys.readouterr().err


def test_scale_on_strand_exporters(tmp_path):
    """--scale multiplies points and widths and divides the metres per unit, for every strand format."""
    src = tmp_path / "in.npz"
    assert main(["synth", "-o", str(src), "--strands", "20", "--points", "8", "--seed", "3"]) == 0
    s = load_strands(src)
    for ext in (".npz", ".hair", ".usda", ".ply"):
        out = tmp_path / f"cm{ext}"
        assert main(["convert", str(src), str(out), "--scale", "100"]) == 0
        back = load_strands(out)
        np.testing.assert_allclose(back.points, 100 * s.points, rtol=1e-6)
        if back.widths is not None:
            np.testing.assert_allclose(back.widths, 100 * s.widths, rtol=1e-6)
        if ext in (".npz", ".usda"):
            assert back.meters_per_unit == pytest.approx(s.meters_per_unit / 100)
