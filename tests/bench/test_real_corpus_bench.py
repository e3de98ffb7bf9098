"""Geometry size on real, un-interpolated hair against the simplest credible coder (``make bench``).

Every model in ../shared/data/hair at its own point counts (each strand's own: a model whose counts
vary is stored with PCNT, spec 3; it is also shown resampled to its largest count) and resampled to
100 points, never densified. For each, the compact profile's geometry chunks (CARD + STRD + CHLD +
PCNT) next to :mod:`baseline_coder` (quantize at the bound, per-strand deltas, zstd -19) at the same
bound (2e-4 of the diagonal) on the same points, and the largest point error of each against the
card builder's float asset *and* against the user's own points.

Figures are printed and kept in pytest-benchmark's JSON; nothing is asserted about sizes or times.
"""

from __future__ import annotations

import numpy as np
import pytest
from hairdata import load_hair

import cghair_format as cgh
from batch import baseline_coder
from batch.baseline_coder import GEOMETRY_CHUNKS
from cghair_format.strands import Strands, resample

pytestmark = pytest.mark.bench

BOUND = 2e-4  # of the bounding-box diagonal: the compact profile's strand-point bound
# one copy of each model: the .data and PLY twins of Bangs_100.hair hold the same strands
MODELS = ["straight.hair", "harolongo.data", "ruby_long_hair_16_guide.tfx", "Ratboy_mohawk.tfx",
          "Bangs_100.hair", "Curly_100.ply"]


def _diagonal(points: np.ndarray) -> float:
    return float(np.linalg.norm(points.max(0) - points.min(0)))


def _ours(strands: Strands, native: bool) -> dict:
    """The compact file of cards built on ``strands``, each strand's own points kept (``native``: its
    error against them is the user's)."""
    from cghair_format.cards import build_cards

    n_cards = int(np.clip(strands.count // 30, 1, 800))
    build = build_cards(strands, n_cards=n_cards, n_groups=min(64, n_cards), seed=0, progress=False)
    data, report = cgh.encode(build.asset, "compact")
    decoded = cgh.decode(data)
    given = cgh.decode_strands(report.in_file_order(build.asset)).points
    diag = _diagonal(strands.points)
    row = {"geometry_bytes": sum(report.chunk_sizes.get(c, 0) for c in GEOMETRY_CHUNKS),
           "file_bytes": len(data),
           "err_vs_given": float(np.linalg.norm(cgh.decode_strands(decoded).points - given, axis=-1).max()) / diag}
    if native:
        row["err_vs_user"] = build.error_of(decoded, report).max_abs / diag
    return row


def _baseline(strands: Strands) -> dict:
    diag = _diagonal(strands.points)
    size, decoded = baseline_coder.encode(strands.points, strands.offsets, BOUND * diag)
    return {"bytes": size, "err": float(np.linalg.norm(decoded - strands.points, axis=-1).max()) / diag}


@pytest.mark.parametrize("model", MODELS)
def test_real_corpus(model, benchmark):
    strands = load_hair(model)
    counts = strands.point_counts
    least, most = int(counts.min()), int(counts.max())
    cases = [(f"native {least}-{most} points" if least < most else f"native {most} points", strands, True),
             ("100 points", resample(strands, 100), False)]
    if least < most:  # what the format's one count per file (2.0) cost: every strand resampled to the largest
        cases.insert(1, (f"resampled to {most} points", resample(strands, most), False))
    lines = [f"\n{model}: {strands.count:,} strands, {least}-{most} points"]
    rows = []
    for name, s, native in cases:
        base = _baseline(s)
        ours = _ours(s, native)
        ratio = ours["geometry_bytes"] / base["bytes"]
        user = f", vs the user's points {ours['err_vs_user']:.2e}" if "err_vs_user" in ours else ""
        lines.append(f"  {name}: geometry {ours['geometry_bytes']:,} B (file {ours['file_bytes']:,}), baseline "
                     f"{base['bytes']:,} B, ratio {ratio:.2f}; max error/diag: ours vs the builder's points "
                     f"{ours['err_vs_given']:.2e}{user}, baseline {base['err']:.2e}")
        rows.append({"model": model, "points": name, "strands": s.count, "geometry B": ours["geometry_bytes"],
                     "file B": ours["file_bytes"], "baseline B": base["bytes"], "ratio": round(ratio, 3),
                     "max err / diag (given)": ours["err_vs_given"],
                     "max err / diag (user)": ours.get("err_vs_user", "resampled"),
                     "baseline max err / diag": base["err"]})
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)  # a table, not a timing: one empty round
    benchmark.extra_info.update({"rows": rows, "table": lines})
    print("\n".join(lines))
