"""``cgh info FILE [--json]``: counts, per-chunk sizes, bits per Gaussian, profile and the strand coder's
settings."""

from __future__ import annotations

import argparse
import json


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="a .cgh file")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")


def run(args: argparse.Namespace) -> int:
    from ..codec import read_info

    info = read_info(args.file)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(format_info(args.file, info))
    return 0


def format_info(name: str, info: dict) -> str:
    fewest, most = info["point_counts"]
    points = f"{most}" if fewest == most else f"{fewest}-{most}"
    lines = [
        f"{name}: .cgh {info['version']}, profile {info['profile']}, {info['file_bytes']:,} bytes",
        f"  strands     {info['strands']:,} x {points} points, "
        f"{info['gaussians']:,} Gaussians ({info['bits_per_gaussian']:.2f} bits per Gaussian)",
        f"  cards       {info['cards']:,} cards of {info['card_segments']} segments, {info['groups']} groups",
        f"  appearance  K={info['codebook_size']} latents of D={info['latent_dim']} per group, "
        f"{info['weight_mode']} weights, MLP {info['latent_dim']}->{'->'.join(map(str, info['mlp']))}, "
        f"SH degree {info['sh_degree']}",
        f"  MLP         {mlp_line(info['mlp_weights'])}",
        f"  scene       thickness {info['thickness']:.3g}, {info['meters_per_unit']:g} m per unit, "
        f"up axis {info['up_axis']}",
        f"  points      {points_line(info)}",
        f"  opacities   {opacity_line(info)}",
        f"  generator   {info['generator']}" + (f"; attribution: {info['attribution']}" if info["attribution"] else ""),
        *([] if info["animation"] is None else [f"  animation   {animation_line(info['animation'])}"]),
        "  chunk  required  codec      stored        raw   share",
    ]
    for c in info["chunks"]:
        lines.append(f"  {c['type']:<6} {'yes' if c['required'] else 'no':<9} {c['codec']:<5} {c['stored_bytes']:>11,} "
                     f"{c['raw_bytes']:>10,} {100 * c['stored_bytes'] / info['file_bytes']:6.1f}%")
    return "\n".join(lines)


def mlp_line(m: dict) -> str:
    """The MLP's weights and biases and what MLPW stores them in (:func:`.codec.read_info`'s ``mlp_weights``)."""
    if m["stored_bytes"] is None:
        return f"{m['values']:,} weights and biases; MLPW is missing"
    return f"{m['values']:,} weights and biases in {m['stored_bytes']:,} bytes, {m['bits_per_value']:.2f} bits each"


def animation_line(a: dict) -> str:
    """The animation (:func:`.codec.read_info`'s ``animation``, spec 4.6) in a line."""
    bound = ("float32 strips (lossless)" if a["bound"] is None else
             f"spine within {a['bound']['spine']:.3g}, normals within {a['bound']['normal_radians']:.2g} rad")
    source = f"; from {a['source']}" if a.get("source") else ""
    return (f"{a['frames']:,} frames at {a['fps']:g} fps from {a['start']:g} s ({a['duration']:.3g} s), a keyframe "
            f"every {a['keyframe_interval']}; {a['bytes_per_frame']:,.0f} bytes a frame, {bound}{source}")


def opacity_line(info: dict) -> str:
    """How near the opacities lie to the writer's input (:func:`.codec.read_info`'s ``opacities``, spec 4.4)."""
    o = info["opacities"]
    if not o["within"]:
        return "stored exactly"
    within = _fraction(o["within"])
    if o["lowered"] is None:
        return f"all within {within} of the writer's input"
    budget = "" if o["budget"] is None else f" (budget {o['budget']:g})"
    return (f"{o['lowered']:,} of {info['gaussians']:,} stored lower, down to 0{budget}; others within {within} "
            "of the writer's input")


def _fraction(x: float) -> str:
    """``x`` as ``1/n`` where that is exact to 4 digits (the profiles' bounds: 1/15, 1/2047), else as is."""
    n = round(1 / x) if 1e-9 < x <= 1 else 0  # (a hostile file's scale may be anything positive)
    return f"1/{n}" if n and abs(n * x - 1) < 1e-4 else f"{x:.3g}"


GUIDES = ("", ", guided by the card neighbour's steps", ", guided by the card neighbour's steps, scaled",
          ", guided by the most alike earlier strand's steps")
LEVEL_GUIDES = ("", ", level residuals as differences from the most alike earlier strand's")


def points_line(info: dict) -> str:
    """How near the strand points lie to the writer's input (spec 7) and the coder's settings, in a line."""
    if info["quant"]["lossless"]:
        return "float32 card coordinates (lossless)"
    return f"{bound_line(info)}, {_coding(info['quant'])}"


def bound_line(info: dict) -> str:
    """How near the strand points lie to the writer's input (:func:`.codec.read_info`'s ``points_within``)."""
    within = info["points_within"]
    if within == 0:
        return "stored exactly"
    if within is None:  # a profile of the caller's own, from before files recorded the bound
        return f"on a step of {info['quant']['step']:.3g} (profile {info['profile']}: bound not recorded)"
    return f"within {within:.3g} of the bbox diagonal"


def _coding(quant: dict) -> str:
    """The strand coder's settings (META quant, spec 4.3 and 4.5) in a line."""
    return (f"step {quant['step']:.3g}, base samples every {quant['base_stride']} points"
            f"{GUIDES[quant['base_guide']]}{LEVEL_GUIDES[quant['level_guide']]}, "
            f"levels interpolating {'/'.join(map(str, quant['level_taps'])) or '-'} points, "
            f"steps stretched up to {quant['stretch_max']:g}x, {quant['neighbour_classes']} neighbour token "
            f"class{'es' if quant['neighbour_classes'] > 1 else ''}"
            + (f"; {quant['children']:,} strands interpolated from 2-3 others (CHLD)" if quant.get("children") else ""))
