"""Builds the codec's compiled kernels (cghair_format/_native.pyx); everything else is in pyproject.toml."""

import sys

from Cython.Build import cythonize
from setuptools import Extension, setup

# No FMA contraction and no fast-math: encoder and decoder must round alike (spec 4.3).
FLAGS = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off", "-fno-fast-math"]

setup(ext_modules=cythonize([Extension("cghair_format._native", ["cghair_format/_native.pyx"],
                                       extra_compile_args=FLAGS)]))
