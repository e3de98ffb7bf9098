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


def _size_table(build) -> tuple[str, dict]:
    from cghair_format.cards import ReconstructionError
    from cghair_format.codec import decode, encode
    from cghair_format.gaussians import decode_points

    lines = ["profile    bytes        bits/Gaussian  mean rel   max rel    encode s"]
    info = {}
    g = build.asset.n_gaussians
    for profile in PROFILES:
        start = time.perf_counter()
        data, _ = encode(build.asset, profile)
        seconds = time.perf_counter() - start
        err = ReconstructionError.measure(build.points, decode_points(decode(data)))
        lines.append(f"{profile:<10}{len(data):>12,}  {8 * len(data) / g:>13.2f}  {err.mean_rel:.2e}  "
                     f"{err.max_rel:.2e}  {seconds:8.1f}")
        info[f"{profile}_bytes"] = len(data)
        info[f"{profile}_max_rel_error"] = err.max_rel
    return "\n".join(lines), info


@pytest.mark.bench
@pytest.mark.slow
def test_cards_paper_scale(benchmark):
    from cghair_format.cards import build_cards

    source, strands = _paper_scale_strands()
    build = benchmark.pedantic(lambda: build_cards(strands, progress=False), rounds=1, iterations=1)
    table, sizes = _size_table(build)
    benchmark.extra_info.update({f"stage_{k}_s": v for k, v in build.timings.items()})
    benchmark.extra_info.update(sizes)
    benchmark.extra_info["max_rel_error_float"] = build.error.max_rel
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
    benchmark.extra_info.update({f"stage_{k}_s": v for k, v in build.timings.items()})
    print(f"\ncard build of straight.hair: {build.info}")
    print(build.timing_table(), end="")
    print(build.error.line("point error before quantization"))
