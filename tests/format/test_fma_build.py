"""The compiled kernels built with FMA contraction forced on (``-O3 -ffp-contract=fast -mfma``) decode
every vector to the same bits: the source pins contraction off (``_arithmetic.pxi``'s pragma, included
by ``_decoder.pyx`` and ``_writer.pyx``), not only setup.py's flags (spec 4, "Arithmetic").

Each build goes to a temporary copy of the package and decodes in a subprocess. A control build of the
same source without the pragma shows that the flags do contract there and change the decoded float64
card coordinates, so the comparison can fail.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
VECTORS = sorted(p for p in (ROOT / "spec" / "vectors").glob("*.cgh") if not p.name.startswith("reject_"))
FLAGS = ["-O3", "-ffp-contract=fast", "-mfma"]

DECODE = """
import sys
from pathlib import Path
import numpy as np
import cghair_format as cgh
from cghair_format import _decoder, codec, strand_coder
from cghair_format.geometry import strand_points

seen = {}
def keep_float64(*args):  # the guides' card coordinates before their rounding to float32
    seen["c"] = strand_coder.decode_coordinates(*args)
    return seen["c"].astype(np.float32)
codec.reader.decode_uvd = keep_float64
out = {"native_file": np.array(_decoder.__file__)}
for path in sys.argv[2:]:
    seen.clear()
    asset = cgh.read(path)
    name = Path(path).stem
    # every point, a variable-count file's placeholders too (spec 3: decoded like the others)
    out[name + ".uvd"], out[name + ".points"] = asset.uvd, strand_points(asset.cards, asset.strand_card, asset.uvd)
    if "c" in seen:
        out[name + ".coordinates"] = seen["c"]
np.savez(sys.argv[1], **out)
"""

BUILD = """
from Cython.Build import cythonize
from setuptools import Extension, setup
setup(ext_modules=cythonize([Extension(f"cghair_format.{{name}}", [f"cghair_format/{{name}}.pyx"],
                                       extra_compile_args={flags!r}) for name in ("_decoder", "_writer")],
                            quiet=True),
      script_args=["build_ext", "--inplace"])
"""


def _cpu_has_fma() -> bool:
    try:
        return " fma " in Path("/proc/cpuinfo").read_text().replace("\n", " ")
    except OSError:
        return False


def _copy(dest: Path, pragma: bool) -> Path:
    shutil.copytree(ROOT / "cghair_format", dest / "cghair_format",
                    ignore=shutil.ignore_patterns("*.so", "*.pyd", "*.c", "__pycache__"))
    if not pragma:
        pxi = dest / "cghair_format" / "_arithmetic.pxi"
        text, n = re.subn(r'cdef extern from \*:\n    """\n.*?    """\n', "", pxi.read_text(), count=1, flags=re.S)
        assert n == 1, "the pragma block of _arithmetic.pxi moved: update this test"
        pxi.write_text(text)
    (dest / "build_fma.py").write_text(textwrap.dedent(BUILD.format(flags=FLAGS)))
    return dest


def _decode_with(package_root: Path, out: Path) -> dict[str, np.ndarray]:
    env = dict(os.environ, PYTHONPATH=str(package_root))
    subprocess.run([sys.executable, "-c", DECODE, str(out)] + [str(p) for p in VECTORS], check=True, env=env,
                   cwd=package_root)
    with np.load(out) as z:
        return dict(z)


@pytest.mark.slow
def test_kernels_built_with_fma_contraction_decode_every_vector_identically(tmp_path):
    if not _cpu_has_fma():
        pytest.skip("this CPU has no FMA instructions: -mfma builds would not run")
    pinned, control = _copy(tmp_path / "pinned", True), _copy(tmp_path / "control", False)
    builds = [subprocess.Popen([sys.executable, "build_fma.py"], cwd=d, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True) for d in (pinned, control)]
    for b in builds:
        log = b.communicate()[0]
        assert b.returncode == 0, log[-3000:]
        assert "-ffp-contract=fast" in log  # the compiler ran with it
    plain = _decode_with(ROOT, tmp_path / "plain.npz")
    fused = _decode_with(pinned, tmp_path / "fused.npz")
    unpinned = _decode_with(control, tmp_path / "control.npz")
    assert str(fused["native_file"]).startswith(str(pinned)) and str(unpinned["native_file"]).startswith(str(control))
    assert not str(plain["native_file"]).startswith(str(tmp_path))
    keys = [k for k in plain if k != "native_file"]
    quantized = [v for v in VECTORS if "lossless" not in v.stem]
    assert sum(k.endswith(".coordinates") for k in keys) >= len(quantized)  # every quantized vector
    for key in keys:
        assert fused[key].tobytes() == plain[key].tobytes(), key
    # without the pragma the same flags contract, and decoding moves
    assert any(unpinned[k].tobytes() != plain[k].tobytes() for k in keys if k.endswith(".coordinates"))
