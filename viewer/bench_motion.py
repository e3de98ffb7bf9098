"""Animated frames against static ones (issue 34, "Speed"; part of ``cgh bench-viewer --animate``).

An animated frame is a static frame (preprocess, sort, gather, draw) after the cards moved: stage
``upload`` writes the cards' spines and normals, ``decode`` rebuilds the card strips, strand points and
the Gaussians' means, rotations and scales on the GPU (the appearance is decoded once, at load). With
``simulate`` the cards come from the live solver (:class:`viewer.motion.LiveSimulation`, one display
frame of 1/30 s a frame, stage ``simulate``); otherwise from a clip (the file's animation, or the
built-in ``nod`` simulated beforehand). Where the renderer turns the SH with their segments (the
default), the animated frame's decode writes the turns and its preprocess applies them; the static frame
applies none, as a static file's frame. Static and animated frames take turns, frame by frame, so a
change of the machine's load weighs on both alike; seconds are medians over the frames, as in
:mod:`viewer.bench`.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from .frame import CARD_STAGES, STAGES

MOTION = "nod"  # the clip simulated when the asset has no animation
MOTION_FPS = 30.0


def bench_clip(asset: Any, frames: int) -> Any:
    """The clip an asset without an animation is timed on: ``frames + 1`` frames of a simulated nod."""
    from cghair_format.animation import simulated_animation

    return simulated_animation(asset, MOTION, frames + 1, MOTION_FPS)


def _medians(rows: list[dict[str, float]], names: tuple[str, ...]) -> dict[str, float]:
    return {f"{k}_s": statistics.median(row.get(k, 0.0) for row in rows) for k in names}


def animated_runs(renderer: Any, asset: Any, cam: Any, settings: Any, budgets: tuple, frames: int,
                  clock: Callable[[Any], Any], animation: Any = None, simulate: bool = False) -> dict:
    """Per budget (``None``: full quality): the static and the animated frame by stage, and their ratio.
    ``renderer`` must have been made with ``animated=True``; its cards are left at rest. ``clock(ctx)``
    makes a frame's stage clock (:class:`viewer.bench.StageClock`)."""
    from .motion import LiveSimulation

    live = LiveSimulation(asset, fps=MOTION_FPS) if simulate else None
    if live is None and animation is None:
        animation = bench_clip(asset, frames)
    moving_stages = (*(("simulate",) if simulate else ()), *CARD_STAGES, *STAGES)
    still_settings = replace(settings, turn_sh=False)  # a static file's frame: no SH turns
    rows, step = [], 0
    for budget in budgets:
        static, moving = [], []
        for _ in range(frames):
            renderer.budget = budget
            timer_static = clock(renderer.ctx)
            renderer.frame(cam, still_settings, timer_static)
            static.append(timer_static.seconds)
            timer_animated = clock(renderer.ctx)
            step += 1
            if live is not None:
                cards = timer_animated("simulate", live.advance)
            else:
                cards = animation.cards(asset.cards, step % animation.frames)
            renderer.move_cards(cards, timer_animated)
            renderer.frame(cam, settings, timer_animated)
            moving.append(timer_animated.seconds)
        still, moved = _medians(static, STAGES), _medians(moving, moving_stages)
        rows.append({"rasterizer": renderer.frame_rasterizer, "budget": budget, "gaussians_drawn": renderer.drawn,
                     "static": still, "static_frame_s": sum(still.values()), "animated": moved,
                     "animated_frame_s": sum(moved.values()),
                     "animated_over_static": sum(moved.values()) / sum(still.values())})
    renderer.move_cards(asset.cards)
    source = "live simulation" if live is not None else (animation.source or "animation")
    return {"source": source, "cards": len(asset.cards.spine), "turn_sh": renderer.scene.geometry.turn is not None,
            "runs": rows}


def format_animated(a: dict) -> list[str]:
    """The report's lines for :func:`animated_runs`."""
    ms = lambda s: f"{1000 * s:8.1f}"  # noqa: E731
    turned = "SH turned with their segments" if a.get("turn_sh") else "SH not turned (--no-turn-sh)"
    lines = [f"animated {a['source']}, {a['cards']:,} cards, {turned}: static frame against animated frame (ms), "
             "animated = simulate + upload + decode + preprocess + sort + gather + draw",
             "rasterizer     budget   static  simulate   upload   decode  splat   animated  animated/static"]
    for run in a["runs"]:
        m = run["animated"]
        splat = sum(m[f"{k}_s"] for k in STAGES)
        budget = "full" if run["budget"] is None else f"{run['budget']:,}"
        sim = ms(m["simulate_s"]) if "simulate_s" in m else "     n/a"
        lines.append(f"{run['rasterizer']:<8} {budget:>12} {ms(run['static_frame_s'])}  {sim} {ms(m['upload_s'])} "
                     f"{ms(m['decode_s'])} {ms(splat)}  {ms(run['animated_frame_s'])}  "
                     f"{run['animated_over_static']:.2f}x")
    if a.get("psnr"):
        lines.append("appearance: PSNR (dB) against the native splatter on frame_gaussians(turn_sh=True), frame by "
                     "frame: the viewer's frame | SH left unturned")
        lines += [f"  frame {row['frame']:>4}   {row['viewer_db']:7.2f} | {row['unturned_db']:7.2f}"
                  for row in a["psnr"]]
    return lines
