"""Builds the compiled kernels: the codec's (cghair_format/_decoder.pyx, _writer.pyx) and training's
(the splatter, training/_raster.pyx; the card-bound Gaussians, training/_geometry.pyx; the SH rows
of the Gaussians shown, training/_rows.pyx); everything else is in pyproject.toml."""

import sys

from Cython.Build import cythonize
from setuptools import Extension, setup

# No FMA contraction and no fast-math: every decoder must round alike (spec 4, "Arithmetic");
# _arithmetic.pxi also pins contraction off in the source, so other flags cannot (tests/format/test_fma_build.py).
FLAGS = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off", "-fno-fast-math"]
# Training's kernels run their loops on every core (OpenMP); they make no bit-exactness promise. Apple's
# clang has no -fopenmp: there its loops run on one core.
if sys.platform == "win32":
    RASTER_FLAGS, RASTER_LINK = ["/O2", "/openmp"], []
elif sys.platform == "darwin":
    RASTER_FLAGS, RASTER_LINK = ["-O3"], []
else:
    RASTER_FLAGS, RASTER_LINK = ["-O3", "-fopenmp"], ["-fopenmp"]

setup(ext_modules=cythonize([
    Extension("cghair_format._decoder", ["cghair_format/_decoder.pyx"], extra_compile_args=FLAGS),
    Extension("cghair_format._writer", ["cghair_format/_writer.pyx"], extra_compile_args=FLAGS),
    Extension("training._raster", ["training/_raster.pyx"], extra_compile_args=RASTER_FLAGS,
              extra_link_args=RASTER_LINK),
    Extension("training._geometry", ["training/_geometry.pyx"], extra_compile_args=RASTER_FLAGS,
              extra_link_args=RASTER_LINK),
    Extension("training._rows", ["training/_rows.pyx"], extra_compile_args=RASTER_FLAGS,
              extra_link_args=RASTER_LINK),
]))
