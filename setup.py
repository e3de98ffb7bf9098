"""Builds the compiled kernels: the codec's (cghair_format/_native.pyx) and the training splatter's
(training/_raster.pyx); everything else is in pyproject.toml."""

import sys

from Cython.Build import cythonize
from setuptools import Extension, setup

# No FMA contraction and no fast-math: encoder and decoder must round alike (spec 4.3).
FLAGS = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off", "-fno-fast-math"]
# The splatter runs its loops on every core (OpenMP); it makes no bit-exactness promise.
RASTER_FLAGS = ["/O2", "/openmp"] if sys.platform == "win32" else ["-O3", "-fopenmp"]
RASTER_LINK = [] if sys.platform == "win32" else ["-fopenmp"]

setup(ext_modules=cythonize([
    Extension("cghair_format._native", ["cghair_format/_native.pyx"], extra_compile_args=FLAGS),
    Extension("training._raster", ["training/_raster.pyx"], extra_compile_args=RASTER_FLAGS,
              extra_link_args=RASTER_LINK),
]))
