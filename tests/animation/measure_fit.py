"""Measure the card fit on simulated strands: ``python tests/animation/measure_fit.py [--strands N]``.

A synthesized groom (``--style``, ``--strands`` x ``--points``) gets cards (``--cards``, the paper's
ratio of 800 cards to 25,000 strands by default); every one of its strands is then simulated on its own
with the built-in solver for each built-in motion, and the asset's cards are fitted to those frames.
Prints, per motion and per number of Gauss-Newton steps, the per-frame point error of the fitted
cards (a fraction of the bbox diagonal: the mean over frames of the mean, the worst frame's mean,
the largest max) and the fit time per frame. ``--driven``: the cards are driven by the solver instead
and their own strand points fitted back (frames the card model holds exactly: what is left is the fit's).
Figures go to docs/animation.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cghair_format.animation import (
    MOTIONS,
    Scene,
    SolverSettings,
    builtin_track,
    fit_head,
    frame_points,
    simulate,
    simulated_animation,
)
from cghair_format.animation.clip import Animation
from cghair_format.animation.fit import fit_frames
from cghair_format.cards import build_cards
from cghair_format.synth import synthesize


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strands", type=int, default=2000)
    ap.add_argument("--points", type=int, default=64)
    ap.add_argument("--cards", type=int, default=None)
    ap.add_argument("--style", default="wavy")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--gn", type=int, nargs="+", default=[0, 2])
    ap.add_argument("--motions", nargs="+", default=list(MOTIONS))
    ap.add_argument("--driven", action="store_true", help="fit the strand points of solver-driven cards")
    args = ap.parse_args()
    cards = args.cards or max(8, round(args.strands * 800 / 25000))
    strands = synthesize(args.style, args.strands, args.points, seed=0)
    asset = build_cards(strands, n_cards=cards, progress=False).asset
    rest = frame_points(asset, Animation.of_frames([asset.cards], args.fps), 0).astype(np.float64)
    head = fit_head(rest[:, 0], rest[:, 1:], asset.up_axis)
    print(f"# {args.style}, {asset.n_strands} strands x {asset.points_per_strand} points, {asset.cards.count} cards "
          f"of {asset.cards.segments} segments; {args.frames} frames at {args.fps:g} fps")
    print(f"{'motion':<7} {'GN':>3} {'mean':>9} {'worst mean':>11} {'max':>9} {'ms/frame':>9} {'sim s':>6}")
    for motion in args.motions:
        t0 = time.perf_counter()
        if args.driven:
            clip = simulated_animation(asset, motion, args.frames, args.fps)
            frames = [frame_points(asset, clip, f).astype(np.float64) for f in range(args.frames)]
        else:
            track = builtin_track(motion, head, args.frames, args.fps, asset.meters_per_unit)
            scene = Scene(track, head.capsules(), asset.meters_per_unit, head.up)
            frames = list(simulate(rest, scene, SolverSettings()))
        sim = time.perf_counter() - t0
        for steps in args.gn:
            _, res = fit_frames(asset, frames, fps=args.fps, refine=steps)
            print(f"{motion:<7} {steps:>3} {res.mean.mean():9.2e} {res.mean.max():11.2e} {res.max.max():9.2e} "
                  f"{1e3 * res.seconds[1:].mean():9.0f} {sim:6.1f}", flush=True)


if __name__ == "__main__":
    main()
