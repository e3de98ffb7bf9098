"""Strand PLY: the hapPLY layout and the fixed-count vertex-only layout.

hapPLY (CT2Hair, hairutil): ``vertex`` (x, y, z, optional red/green/blue, optional thickness),
``strand`` (``nsegs`` per strand: the strand has ``nsegs + 1`` consecutive vertices) and ``edge``
(vertex1, vertex2; redundant with ``strand``). Files with only ``edge`` are split where
consecutive vertices are not joined by an edge. Vertex-only files come in two kinds:
- strands of one fixed point count (GaussianHaircut's ``src/preprocessing/export_curves.py`` writes
  ``L = 100`` points per strand as float ``x y z nx ny nz`` with zero normals): the count is
  ``points_per_strand``, else a ``comment points_per_strand N`` header line, else 100 when it
  divides the vertex count;
- strands told apart by their colour (one colour per strand, the layout some reconstruction tools
  write; CT2Hair's files have such colours too): a strand ends where the colour changes.
Colours delimit strands when every run of one colour has at least 2 vertices (otherwise they are
per-vertex colours). When a fixed count also applies, it is used if every colour change falls on a
multiple of it (it also separates neighbours that happen to share a colour); a count that was
stated (argument or header) and disagrees with the colours is refused, an assumed 100 gives way.
PLY names no units or up axis.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..strands import Strands
from ._common import StrandFileError, finish, float32, offsets_from_counts
from ._ply import read_ply, write_ply

DEFAULT_FIXED_COUNT = 100
COUNT_PROPS = ("nsegs", "num_segments", "segments")
ID_PROPS = ("strand_id", "curve_id", "strand")


def load(path: str | Path, points_per_strand: int | None = None) -> Strands:
    ply = read_ply(path)
    vertex = ply.elements.get("vertex")
    if vertex is None or not {"x", "y", "z"} <= set(vertex.data):
        raise StrandFileError(path, "PLY file has no 'vertex' element with x, y, z")
    v = vertex.data
    if "f_dc_0" in v and "strand" not in ply.elements:
        raise StrandFileError(path, "this is a 3D Gaussian splat PLY, not strands: read it with "
                                    "read_3dgs_ply, or convert it with cgh export FILE -o out.usda")
    points = float32(path, "vertex x, y, z", np.stack([v["x"], v["y"], v["z"]], 1))
    n = len(points)
    counts = _strand_counts(path, ply, v, n, points_per_strand)
    if int(counts.sum()) != n or (counts < 1).any():
        raise StrandFileError(path, f"strand sizes add up to {int(counts.sum())} vertices, the file has {n}")
    colors = _colors(v)
    widths, fields = None, {"colors": "vertex colours"}
    for name in ("thickness", "width"):
        if name in v:
            fields["widths"] = f"vertex property {name!r}"
            widths = float32(path, fields["widths"], v[name])
            break
    return finish(path, Strands(points, offsets_from_counts(counts), colors, widths), fields)


def _strand_counts(path, ply, v, n: int, points_per_strand: int | None) -> np.ndarray:
    strand = ply.elements.get("strand")
    if strand is not None:
        for name in COUNT_PROPS:
            if name in strand.data:
                return np.asarray(strand.data[name], np.int64) + 1
        raise StrandFileError(path, f"PLY 'strand' element has none of {COUNT_PROPS}")
    for name in ID_PROPS:
        if name in v:
            ids = np.asarray(v[name])
            breaks = np.flatnonzero(ids[1:] != ids[:-1]) + 1
            return np.diff(np.concatenate([[0], breaks, [n]]))
    edge = ply.elements.get("edge")
    if edge is not None and {"vertex1", "vertex2"} <= set(edge.data):
        a = np.asarray(edge.data["vertex1"], np.int64)
        b = np.asarray(edge.data["vertex2"], np.int64)
        joined = np.zeros(max(n - 1, 0), bool)
        ok = (b == a + 1) & (a >= 0) & (a < n - 1)
        joined[a[ok]] = True
        breaks = np.flatnonzero(~joined) + 1
        return np.diff(np.concatenate([[0], breaks, [n]]))
    stated = points_per_strand
    if stated is None:
        for c in ply.comments:
            parts = c.split()
            if len(parts) == 2 and parts[0] in ("points_per_strand", "strand_points"):
                if not parts[1].isdigit():
                    raise StrandFileError(path, f"PLY comment {c!r} needs a whole number of points")
                stated = int(parts[1])
    p = stated if stated is not None else (DEFAULT_FIXED_COUNT if n % DEFAULT_FIXED_COUNT == 0 else None)
    runs = _colour_runs(v, n)
    if runs is not None:
        changes = np.cumsum(runs)[:-1]
        if p is not None and p >= 2 and n % p == 0 and not (changes % p).any():
            return np.full(n // p, p, np.int64)
        if stated is not None:
            raise StrandFileError(path, f"vertex-only strand PLY: its per-strand colours split {n} vertices into "
                                        f"{len(runs)} strands of {runs.min()}..{runs.max()} points, which disagrees "
                                        f"with {stated} points per strand; drop the count to split by colour")
        return runs
    if p is None or p < 2 or n % p:
        raise StrandFileError(path, f"vertex-only strand PLY: cannot split {n} vertices into strands of "
                                    f"{p or DEFAULT_FIXED_COUNT} points; give the count with "
                                    "--points-per-strand (points_per_strand=)")
    return np.full(n // p, p, np.int64)


def _colour_runs(v: dict, n: int) -> np.ndarray | None:
    """Lengths of the runs of consecutive vertices of one colour, when colours delimit strands (every
    run at least 2 vertices long, more than one run); else None."""
    for names in (("red", "green", "blue"), ("r", "g", "b")):
        if all(k in v for k in names):
            c = np.stack([np.asarray(v[k]) for k in names], 1)
            changes = np.flatnonzero((c[1:] != c[:-1]).any(1)) + 1
            runs = np.diff(np.concatenate([[0], changes, [n]]))
            return runs if len(runs) > 1 and runs.min() >= 2 else None
    return None


def _colors(v: dict) -> np.ndarray | None:
    for names in (("red", "green", "blue"), ("r", "g", "b")):
        if all(k in v for k in names):
            c = np.stack([np.asarray(v[k]) for k in names], 1)
            if np.issubdtype(c.dtype, np.integer):
                return (c.astype(np.float32) / np.iinfo(c.dtype).max).astype(np.float32)
            return c.astype(np.float64)  # checked and clipped to [0, 1] by finish
    return None


def save(strands: Strands, path: str | Path) -> None:
    """Write the hapPLY layout (binary little-endian): vertex, strand nsegs, edge."""
    counts = strands.point_counts
    if (counts < 1).any() or (counts > 65536).any():
        raise StrandFileError(path, "strand PLY stores 1..65536 points per strand (nsegs is a ushort)")
    vertex = {"x": strands.points[:, 0].astype(np.float32), "y": strands.points[:, 1].astype(np.float32),
              "z": strands.points[:, 2].astype(np.float32)}
    if strands.colors is not None:
        rgb = np.clip(np.rint(strands.colors * 255), 0, 255).astype(np.uint8)
        vertex.update(red=rgb[:, 0], green=rgb[:, 1], blue=rgb[:, 2])
    if strands.widths is not None:
        vertex["thickness"] = strands.widths.astype(np.float32)
    idx = np.arange(len(strands.points), dtype=np.int64)
    last = np.zeros(len(idx), bool)
    last[strands.offsets[1:] - 1] = True
    starts = idx[~last]
    edge = {"vertex1": starts.astype(np.int32), "vertex2": (starts + 1).astype(np.int32)}
    nsegs = {"nsegs": (counts - 1).astype(np.uint16)}
    write_ply(path, [("vertex", vertex), ("strand", nsegs), ("edge", edge)],
              comments=["Written by cghair (hapPLY strand layout)"])
