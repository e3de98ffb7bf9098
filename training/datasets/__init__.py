"""Multi-view datasets: what training, evaluation and reconstruction read.

Modules, each importing only those above it in this list:

- :mod:`.types`: :class:`View`, :class:`Dataset`, :class:`DatasetError`, the train / val / test split;
- :mod:`.colmap`: COLMAP sparse models (binary or text);
- :mod:`.nerf`: the NeRF-synthetic layout, read and written;
- :mod:`.layouts`: which layout a folder holds; :mod:`.capture`: COLMAP and GaussianHaircut captures;
- :mod:`.read`: :func:`read_dataset`, any layout;
- :mod:`.alignment`: do the strands sit where the views see hair (checked before training);
- :mod:`.cameras`, :mod:`.colours`, :mod:`.cycles`, :mod:`.synthetic`: datasets rendered from strands
  (:func:`render_dataset`), by the splat engine or Blender Cycles.

Nothing here imports the rest of :mod:`training` at import time; the splat engine imports the
rasterizers (:mod:`training.backends`) when it renders.
"""
