"""Checks of the strand solver that docs/animation.md records: its discretization and its stability.

    python tools/animation_checks.py discretization [--model harolongo.data|STYLE] [--strands 2000] [--cards 64]
        [--motion nod] [--frames 45] [--png PICTURE.png]
    python tools/animation_checks.py stability [--seconds 2] [--styles ...] [--models ...]
    python tools/animation_checks.py paper [--strands 2500] [--motion nod] [--frames 60]

``discretization``: a real model's own strands (a seeded subset) or a built-in style's (grown at 200
points), resampled (B-spline) to 32 and to 100
points, each built into cards; per point count the solver runs on the cards' spines and on every
strand alone, and the strands decoded from the driven cards are compared with the strands simulated
alone (mean point distance over the rest bounding-box diagonal, each frame). The strands alone at 32
and at 100 points are also compared with each other at matching arc lengths: the solver's own
discretization. ``--png`` draws, side on (across the nod's axis), the driven strands beside the
strands alone at the worst frame of each point count.

``stability``: every built-in style (1,000 strands x 32 points, 64 cards) and every real model (its
own strands; 16 cards for those of 100), the cards driven by each built-in motion at 30 and at 60 fps
with the default settings: every frame finite, the largest relative segment length error, and the
fastest spine point's speed in bounding-box diagonals a second.

``paper``: the paper-scale benchmark's point errors (tests/bench/test_animation_bench.py: harolongo
25,000 x 100 on 800 cards, 60 frames at 30 fps) with the all-strand reference simulated for a seeded
subset of the strands only (each strand alone moves the same in any company), for a shared machine
where all 25,000 would take hours; no rendering. It reads the bench's cached asset (``--asset``).

All print one line a case; run from the repository root, whose ``cghair_format`` they use.
Real models are read from ../shared/data/hair; nothing derived from them is written (draw the picture
of a built-in style for the repository: docs/images/animation_breaks.png is ``--model long``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

from cghair_format.animation import MOTIONS, Scene, SolverSettings, builtin_track, card_frames, fit_head, simulate  # noqa: E402
from cghair_format.geometry import arc_shares, at_arc_shares, bounding_diagonal, strand_points  # noqa: E402
from cghair_format.strands import Strands, resample  # noqa: E402

HAIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "hair"
# metres per unit of each real model (PROVENANCE.md: centimetres; ruby's guides are 2.5 mm a unit)
MODELS = {"straight.hair": (0.01, "Z"), "harolongo.data": (0.01, None), "ruby_long_hair_16_guide.tfx": (0.0025, None),
          "Ratboy_mohawk.tfx": (0.01, None), "Bangs_100.hair": (0.01, None), "Curly_100.ply": (0.01, None)}
STYLES = ("straight", "wavy", "curly", "coily", "short", "long", "ponytail")


def load_model(name: str) -> Strands:
    from cghair_format.exchange import load_strands

    units, up = MODELS[name]
    return load_strands(HAIR / name, units=units, up=up)


def scene_of(asset, rest: np.ndarray, motion: str, frames: int, fps: float) -> Scene:
    """The bench's scene: the head fitted to the decoded strands' roots, clear of them and the spines."""
    others = np.concatenate([rest[:, 1:].reshape(-1, 3), asset.cards.spine[:, 1:].reshape(-1, 3)])
    head = fit_head(rest[:, 0], others, asset.up_axis)
    track = builtin_track(motion, head, frames, fps, asset.meters_per_unit)
    return Scene(track, head.capsules(), asset.meters_per_unit, head.up)


def driven_against_alone(strands: Strands, points: int, cards: int, motion: str, frames: int) -> dict:
    """Cards built from ``strands`` at ``points`` points, driven, against the strands simulated alone."""
    from cghair_format.cards import build_cards

    resampled = resample(strands, points, method="bspline")
    asset = build_cards(resampled, n_cards=cards, n_groups=min(8, cards), points=points, seed=0,
                        progress=False).asset
    rest = strand_points(asset.cards, asset.strand_card, asset.uvd).astype(np.float64)
    scene, settings, diag = scene_of(asset, rest, motion, frames, 30.0), SolverSettings(), bounding_diagonal(rest)
    t = time.perf_counter()
    driven = [strand_points(c, asset.strand_card, asset.uvd) for c in card_frames(asset.cards, scene, settings)]
    card_s = time.perf_counter() - t
    t = time.perf_counter()
    alone = list(simulate(rest, scene, settings))
    alone_s = time.perf_counter() - t
    err = [float(np.linalg.norm(d - a, axis=-1).mean()) / diag for d, a in zip(driven, alone, strict=True)]
    return dict(points=points, rest=rest, driven=driven, alone=alone, err=err, diag=diag, up=scene.up,
                card_s=card_s, alone_s=alone_s)


def discretization(args: argparse.Namespace) -> None:
    if args.model in STYLES:
        from cghair_format.synth import synthesize

        strands, keep = synthesize(args.model, args.strands, 200, seed=0), np.arange(args.strands)
    else:
        strands = load_model(args.model)
        keep = np.sort(np.random.default_rng(0).choice(strands.count, min(args.strands, strands.count), replace=False))
        strands = _subset(strands, keep)
    runs = [driven_against_alone(strands, p, args.cards, args.motion, args.frames) for p in (32, 100)]
    for r in runs:
        e = np.array(r["err"])
        print(f"{args.model} {len(keep)} strands x {r['points']} points, {args.cards} cards, {args.motion} "
              f"{args.frames} frames: cards vs strands alone, mean {e.mean():.4f} of the diagonal, "
              f"frames 5+ {e[5:].min():.4f}-{e[5:].max():.4f}, worst frame {int(e.argmax())} "
              f"(simulation {r['card_s']:.1f} s cards, {r['alone_s']:.1f} s strands)", flush=True)
    coarse, fine = runs
    shares, fine_shares = arc_shares(coarse["rest"]), arc_shares(fine["rest"])
    gap = [float(np.linalg.norm(a - at_arc_shares(b, fine_shares, shares), axis=-1).mean()) / coarse["diag"]
           for a, b in zip(coarse["alone"], fine["alone"], strict=True)]
    print(f"strands alone, 32 against 100 points at matching arc lengths: mean {np.mean(gap):.4f}, "
          f"worst frame {max(gap):.4f} of the diagonal")
    if args.png:
        draw(runs, args.png, f"{args.model}, {len(keep)} strands, {args.cards} cards, {args.motion}")


def _subset(strands: Strands, keep: np.ndarray) -> Strands:
    counts = strands.point_counts
    parts = [strands.strand(int(i)) for i in keep]
    offsets = np.concatenate([[0], np.cumsum(counts[keep])]).astype(np.int64)
    return Strands(np.concatenate(parts).astype(np.float32), offsets, meters_per_unit=strands.meters_per_unit,
                   up_axis=strands.up_axis)


def draw(runs: list[dict], path: str, title: str, shown: int = 120, size: int = 420) -> None:
    """Side views (the nod's axis, x, into the page) at each run's worst frame: strands alone in blue,
    the same strands decoded from the driven cards in orange."""
    from PIL import Image, ImageDraw

    image = Image.new("RGB", (size * len(runs), size + 40), "white")
    pen = ImageDraw.Draw(image)
    pen.text((8, 4), title, fill="black")
    for i, r in enumerate(runs):
        f = int(np.argmax(r["err"]))
        pick = np.linspace(0, len(r["rest"]) - 1, shown).astype(int)
        up = 1 if abs(r["up"][1]) > 0.5 else 2
        side = 2 if up == 1 else 1
        views = [r["alone"][f][pick], r["driven"][f][pick].astype(np.float64), r["alone"][0][pick]]
        allp = np.concatenate([v.reshape(-1, 3) for v in views])
        lo, hi = allp.min(0), allp.max(0)
        scale = (size - 30) / max(hi[side] - lo[side], hi[up] - lo[up])

        def xy(p: np.ndarray, lo=lo, scale=scale, i=i, side=side, up=up) -> list[tuple[float, float]]:
            return [(i * size + 15 + (q[side] - lo[side]) * scale, size + 15 - (q[up] - lo[up]) * scale)
                    for q in p]

        for strand_alone, strand_driven in zip(views[0], views[1], strict=True):
            pen.line(xy(strand_alone), fill=(40, 90, 200), width=1)
            pen.line(xy(strand_driven), fill=(240, 130, 20), width=1)
        pen.text((i * size + 8, 20), f"{r['points']} points, frame {f}: mean {r['err'][f]:.3f} of the diagonal "
                 "(blue alone, orange cards)", fill="black")
    image.save(path, optimize=True)
    print(f"wrote {path} ({Path(path).stat().st_size:,} bytes)")


def paper(args: argparse.Namespace) -> None:
    import cghair_format as cgh

    asset = cgh.read(args.asset)
    asset.meters_per_unit = 0.01  # harolongo is modelled in centimetres, as in the bench
    rest = strand_points(asset.cards, asset.strand_card, asset.uvd).astype(np.float64)
    scene = scene_of(asset, rest, args.motion, args.frames, 30.0)
    keep = np.sort(np.random.default_rng(0).choice(len(rest), min(args.strands, len(rest)), replace=False))
    t = time.perf_counter()
    cards = list(card_frames(asset.cards, scene, SolverSettings()))
    card_s = (time.perf_counter() - t) / args.frames
    t = time.perf_counter()
    alone = list(simulate(rest[keep], scene, SolverSettings()))
    alone_s = (time.perf_counter() - t) / args.frames
    diag, mean_err, max_err = bounding_diagonal(rest), [], []
    for c, a in zip(cards, alone, strict=True):
        err = np.linalg.norm(strand_points(c, asset.strand_card[keep], asset.uvd[keep]) - a, axis=-1) / diag
        mean_err.append(float(err.mean()))
        max_err.append(float(err.max()))
    print(f"{args.motion}, {args.frames} frames, {asset.cards.count} cards, {len(keep)} of {len(rest)} strands x "
          f"{rest.shape[1]}: mean err / diag {np.mean(mean_err):.4f}, worst frame mean {max(mean_err):.4f} "
          f"(frame {int(np.argmax(mean_err))}), max {max(max_err):.3f}; simulation {1e3 * card_s:.0f} ms a frame "
          f"for the cards, {alone_s:.2f} s a frame for {len(keep)} strands")


def grooms(styles: list[str], models: list[str]):
    """``(name, strands, cards)`` for each built-in style and each real model."""
    from cghair_format.synth import synthesize

    for style in styles:
        yield style, synthesize(style, 1000, 32, seed=0), 64
    for model in models:
        strands = load_model(model)
        yield model, strands, 16 if strands.count <= 100 else 64


def stability(args: argparse.Namespace) -> None:
    from cghair_format.animation.tracks import head_of
    from cghair_format.cards import build_cards

    for name, strands, n_cards in grooms(args.styles, args.models):
        asset = build_cards(strands, n_cards=n_cards, n_groups=min(8, n_cards), seed=0, progress=False).asset
        head = head_of(asset)
        rest = asset.cards.spine.astype(np.float64)
        rest_len = np.linalg.norm(np.diff(rest, axis=1), axis=-1)
        diag = bounding_diagonal(strand_points(asset.cards, asset.strand_card, asset.uvd))
        for fps in (30.0, 60.0):
            for motion in MOTIONS:
                frames = int(round(args.seconds * fps))
                track = builtin_track(motion, head, frames, fps, asset.meters_per_unit)
                scene = Scene(track, head.capsules(), asset.meters_per_unit, head.up)
                spines = np.stack(list(simulate(rest, scene, SolverSettings())))  # the cards' spines, float64
                finite = bool(np.isfinite(spines).all())
                length = np.linalg.norm(np.diff(spines, axis=2), axis=-1)
                length_err = float(np.abs(length / np.maximum(rest_len, 1e-30) - 1).max())
                speed = float(np.linalg.norm(np.diff(spines, axis=0), axis=-1).max()) * fps / diag
                print(f"{name:28s} {motion:6s} {fps:3.0f} fps: finite {finite}, length error {length_err:.1e}, "
                      f"fastest spine point {speed:.1f} diagonals/s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    verbs = parser.add_subparsers(dest="verb", required=True)
    d = verbs.add_parser("discretization", help="cards against strands alone, at 32 and at 100 points")
    d.add_argument("--model", default="harolongo.data", choices=list(MODELS) + list(STYLES))
    d.add_argument("--strands", type=int, default=2000, help="a seeded subset of the model's strands")
    d.add_argument("--cards", type=int, default=64)
    d.add_argument("--motion", default="nod", choices=MOTIONS)
    d.add_argument("--frames", type=int, default=45)
    d.add_argument("--png", default=None, help="draw the worst frames here")
    s = verbs.add_parser("stability", help="every style and model, every motion, 30 and 60 fps")
    s.add_argument("--seconds", type=float, default=2.0)
    s.add_argument("--styles", nargs="*", default=list(STYLES))
    s.add_argument("--models", nargs="*", default=list(MODELS))
    q = verbs.add_parser("paper", help="the paper-scale bench's point errors, strands alone on a subset")
    q.add_argument("--asset", default=".pytest_cache/d/cghair_paper_scale/harolongo_25000x100_800c64g.cgh")
    q.add_argument("--strands", type=int, default=2500, help="a seeded subset simulated alone")
    q.add_argument("--motion", default="nod", choices=MOTIONS)
    q.add_argument("--frames", type=int, default=60)
    args = parser.parse_args()
    {"discretization": discretization, "stability": stability, "paper": paper}[args.verb](args)


if __name__ == "__main__":
    main()
