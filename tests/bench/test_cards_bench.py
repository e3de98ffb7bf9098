"""Card builder timings and .cgh sizes at the paper's scale (25,000 strands x 100 points).

Reports figures (printed and in the benchmark's extra_info); never asserts times. The input is
real hair densified to 25,000 strands (``strands.densify`` of harolongo.data from ../shared), or
procedural wavy hair when ../shared is absent. Run with ``make bench``.
"""

from __future__ import annotations

import time

import pytest
from hairdata import HAIR_DIR, hair_path

pytest.importorskip("sklearn", reason="the card builder needs scikit-learn (pip install 'cghair[cards]')")

PAPER_STRANDS = 25_000
PAPER_POINTS = 100
PROFILES = ("lossless", "high", "compact")


def _paper_scale_strands():
    from cghair_format.strands import densify

    src = HAIR_DIR / "harolongo.data"
    if src.exists():  # else a procedural stand-in, named as such in the printed table
        from cghair_format.exchange import load_strands

        return "harolongo.data densified", densify(load_strands(src), PAPER_STRANDS, seed=0, n_points=PAPER_POINTS)
    from cghair_format.synth import synthesize

    return "procedural wavy", synthesize("wavy", PAPER_STRANDS, PAPER_POINTS, seed=0)


def _size_table(build) -> tuple[str, list[dict]]:
    from cghair_format.cards import ReconstructionError
    from cghair_format.codec import decode, encode
    from cghair_format.gaussians import decode_points

    lines = ["profile    bytes        bits/Gaussian  mean rel   max rel    encode s"]
    rows = []
    g = build.asset.n_gaussians
    for profile in PROFILES:
        start = time.perf_counter()
        data, report = encode(build.asset, profile)
        seconds = time.perf_counter() - start
        # the quantized profiles store the strands card by card: compare in the file's order
        err = ReconstructionError.measure(report.strands_in_file_order(build.points), decode_points(decode(data)))
        lines.append(f"{profile:<10}{len(data):>12,}  {8 * len(data) / g:>13.2f}  {err.mean_rel:.2e}  "
                     f"{err.max_rel:.2e}  {seconds:8.1f}")
        rows.append({"profile": profile, "bytes": len(data), "bits/Gaussian": round(8 * len(data) / g, 2),
                     "mean rel err": err.mean_rel, "max rel err": err.max_rel, "encode s": seconds})
    return "\n".join(lines), rows


def _build_row(source: str, build) -> dict:
    """One table row: the input, the build's shape, its seconds per stage and the float error."""
    return {"input": source, **{k: build.info[k] for k in ("strands", "points", "cards", "groups")},
            **{f"{k} s": v for k, v in build.timings.items()}, "total s": sum(build.timings.values()),
            "max rel err (float)": build.error.max_rel}


@pytest.mark.bench
@pytest.mark.slow
def test_cards_paper_scale(benchmark):
    from cghair_format.cards import build_cards

    source, strands = _paper_scale_strands()
    build = benchmark.pedantic(lambda: build_cards(strands, progress=False), rounds=1, iterations=1)
    table, sizes = _size_table(build)
    benchmark.extra_info.update({"rows": [_build_row(source, build)], "sizes": sizes})
    print(f"\ncard build of {source}: {build.info}")
    print(build.timing_table(), end="")
    print(build.error.line("point error before quantization"))
    print(table)
    assert build.info["strands"] == PAPER_STRANDS and build.asset.uvd.shape[1] == PAPER_POINTS


@pytest.mark.bench
@pytest.mark.slow
def test_cards_straight_hair(benchmark):
    src = hair_path("straight.hair")
    from cghair_format.cards import build_cards
    from cghair_format.exchange import load_strands

    strands = load_strands(src)
    build = benchmark.pedantic(lambda: build_cards(strands, progress=False), rounds=1, iterations=1)
    benchmark.extra_info["rows"] = [_build_row("straight.hair", build)]
    print(f"\ncard build of straight.hair: {build.info}")
    print(build.timing_table(), end="")
    print(build.error.line("point error before quantization"))
