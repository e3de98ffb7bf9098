"""A head track read from a DCC tool's file: the animated transform of the head's prim in USD or
Alembic (:mod:`cghair_format.exchange.xform_track`) made a :class:`~.tracks.HeadTrack` of an asset.

A track maps the asset's rest pose to each frame. Which pose of the head the .cgh holds is ``rest``:

- ``"first"`` (the default): the groom as it sits on the head at the track's first frame (a groom
  exported from the scene at that frame); frame ``f`` is ``W_f W_0^-1``, and frame 0 is the identity.
- ``"local"``: the groom in the head prim's own space (its untransformed pose, as a groom bound to the
  head is authored); frame ``f`` is ``W_f``.

``W_f`` is the prim's world transform at frame ``f``. The track is brought to the asset's units (the
file's ``metersPerUnit`` when it states one, else the asset's own; Alembic is metres) and up axis (a
z-up file's track turned into a y-up asset's frame and back). A head moves rigidly: a track that
scales, shears or mirrors it beyond :data:`RIGID_TOLERANCE` is refused rather than silently stripped,
since a scaled head would leave the groom's roots off its scalp (a constant scale on the prim, as a
cm-to-m rig carries, cancels in ``"first"``); within the tolerance the nearest rotation is kept.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import CghError
from .tracks import HeadTrack

RESTS = ("first", "local")
RIGID_TOLERANCE = 1e-3  # largest deviation of a singular value of the 3x3 part from 1
# x, y, z of a z-up frame in a y-up one (z-up's up is y-up's up, z-up's forward y is y-up's -z)
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def file_axes(file_up: str | None, asset_up: str) -> np.ndarray:
    """The rotation taking the file's axes to the asset's (identity when the file states no up axis)."""
    if file_up is None or file_up == asset_up:
        return np.eye(3)
    return Z_UP_TO_Y_UP if asset_up == "Y" else Z_UP_TO_Y_UP.T


def track_from_matrices(matrix: np.ndarray, fps: float, start: float = 0.0, *, rest: str = "first",
                        scale: float = 1.0, axes: np.ndarray | None = None, name: str = "the track") -> HeadTrack:
    """The :class:`HeadTrack` of world transforms ``matrix [F, 4, 4]`` (column vectors): relative to the
    first frame or as they are (``rest``), lengths times ``scale`` (file units to the asset's), turned
    into the asset's axes by the rotation ``axes``; a non-rigid frame raises a one-line :class:`CghError`."""
    if rest not in RESTS:
        raise CghError(f"unknown head rest {rest!r}; choose one of {', '.join(RESTS)}")
    m = np.asarray(matrix, np.float64)
    if m.ndim != 3 or m.shape[1:] != (4, 4) or len(m) < 1 or not np.isfinite(m).all():
        raise CghError(f"{name}: a track needs finite [F, 4, 4] matrices, got shape {m.shape}")
    if rest == "first":
        try:
            m = m @ np.linalg.inv(m[0])
        except np.linalg.LinAlgError:
            raise CghError(f"{name}: the first frame's transform is singular (scaled to nothing)") from None
    linear, translation = m[:, :3, :3], m[:, :3, 3]
    sv = np.linalg.svd(linear, compute_uv=False)
    off = np.abs(sv - 1).max(1)
    mirrored = np.linalg.det(linear) < 0
    if (off > RIGID_TOLERANCE).any() or mirrored.any():
        f = int(np.argmax((off > RIGID_TOLERANCE) | mirrored))
        hint = " or use --head-rest first" if rest == "local" else ""
        raise CghError(f"{name}: the head's transform at frame {f} is not rigid (stretch {sv[f].min():.4g}.."
                       f"{sv[f].max():.4g}{', mirrored' if mirrored[f] else ''}); a head track must only turn "
                       f"and move: bake the scale into the groom{hint}")
    u, _, vt = np.linalg.svd(linear)
    rotation = u @ vt  # the nearest rotation: drops what is left of the stretch within the tolerance
    c = np.eye(3) if axes is None else np.asarray(axes, np.float64)
    return HeadTrack(c @ rotation @ c.T, (translation * scale) @ c.T, float(fps), float(start))


def head_track_from_file(path: str | Path, asset, prim: str | None = None, rest: str = "first") -> HeadTrack:
    """The head track of ``asset`` (a :class:`~cghair_format.asset.HairAsset`) read from the animated
    transform of ``prim`` (or the single animated xformable prim) of a USD or Alembic file."""
    from ..exchange.xform_track import load_xforms

    samples = load_xforms(path, prim)
    # a file that states no units is taken in the asset's (as a strand cache is, animation.fit)
    scale = 1.0 if samples.meters_per_unit is None else samples.meters_per_unit / asset.meters_per_unit
    return track_from_matrices(samples.matrix, samples.fps, samples.start, rest=rest, scale=scale,
                               axes=file_axes(samples.up_axis, asset.up_axis), name=f"{path} ({samples.prim})")
