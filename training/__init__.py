"""Training of the compact appearance model: reference splatter, datasets, model, evaluation.

Needs the ``training`` extra (torch). ``import training`` itself imports nothing heavy.
"""

import os

# Torch's OpenMP threads and the compiled kernels' (another OpenMP runtime) take turns every few
# milliseconds; threads left spinning by one hold the cores the other needs, which on a busy
# machine multiplies an iteration's time (docs/training.md, "Threads"). Set before either runtime
# starts; a user's own OMP_WAIT_POLICY wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
