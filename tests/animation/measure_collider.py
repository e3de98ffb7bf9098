"""Measure the head-mesh collider: ``python tests/animation/measure_collider.py GROOM.cgh [--motion nod]``.

The groom must be a built-in style's (``cgh synth``, then ``cgh cards``): its head is the synthesizer's
ellipsoid (:data:`cghair_format.synth.HEAD_RADII`, metres, y up), which this script meshes and uses as
the scalp mesh. Prints the cost of the distance field's build, of the collision pass a frame (alone, on
the clip's own frames, as often as the solver calls it) and of the whole simulation with the fitted
sphere and with the mesh; then, for the rest pose and every frame, how deep the deepest card spine
point past the root (and past the first quarter of its spine) lies inside the head mesh under each.
Figures go to docs/animation.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from head_helpers import sphere_mesh

from cghair_format.animation import MOTIONS, SolverSettings, StrandState, builtin_track, simulated_animation
from cghair_format.animation.collider import collider_field, depth_inside
from cghair_format.animation.solver import collide_field
from cghair_format.animation.tracks import head_of
from cghair_format.codec import read
from cghair_format.exchange.meshes import TriangleMesh
from cghair_format.synth import HEAD_CENTER, HEAD_RADII


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("groom")
    ap.add_argument("--motion", choices=MOTIONS, default="nod")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--rings", type=int, default=64, help="bands of the head mesh, pole to pole")
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--stiffness", type=float, default=None, help="bend stiffness (default: the solver's)")
    args = ap.parse_args()
    asset = read(args.groom)
    unit = asset.meters_per_unit
    vertices, triangles = sphere_mesh(1.0, rings=args.rings)
    mesh = TriangleMesh((vertices * HEAD_RADII + HEAD_CENTER) / unit, triangles)
    print(f"# {asset.cards.count} cards x {asset.cards.segments} segments, head mesh {len(triangles)} triangles")
    t = time.perf_counter()
    field = collider_field(asset, mesh, args.resolution)
    print(f"field: {'x'.join(map(str, field.distance.shape))}, cell {field.cell * unit * 1e3:.2f} mm, "
          f"built in {time.perf_counter() - t:.2f} s")
    settings = SolverSettings() if args.stiffness is None else SolverSettings(local_stiffness=args.stiffness)
    head, still = head_of(asset), (np.eye(3), np.zeros(3))
    track = builtin_track(args.motion, head, args.frames, args.fps, unit)
    runs = {}
    for name, collider in (("sphere", None), ("mesh", field)):
        t = time.perf_counter()
        runs[name] = simulated_animation(asset, args.motion, args.frames, args.fps, settings, 0, collider)
        print(f"simulation with the {name}: {1e3 * (time.perf_counter() - t) / args.frames:.0f} ms a frame "
              f"(with a {settings.settle:g} s settle)")
    calls = settings.substeps * settings.length_iterations
    t = time.perf_counter()
    for f in range(args.frames):
        state = StrandState.at_rest(runs["mesh"].spine[f].astype(np.float64))
        for _ in range(calls):
            collide_field(state, field, *track.at(f / args.fps))
    print(f"collide_field alone: {1e3 * (time.perf_counter() - t) / args.frames:.1f} ms a frame ({calls} calls)")
    rest = asset.cards.spine.astype(np.float64)
    swing = asset.cards.segments // 4 + 1  # the spine past its first quarter: what swings
    print(f"rest pose: deepest spine point past the root {depth_inside(field, rest[:, 1:], *still) * unit * 1e3:.2f}"
          f" mm inside, past the first quarter {depth_inside(field, rest[:, swing:], *still) * unit * 1e3:.2f} mm")
    print(f"{'frame':>5} {'sphere mm':>10} {'(swing)':>8} {'mesh mm':>8} {'(swing)':>8}")
    depth = {(name, first): [depth_inside(field, run.spine[f][:, first:], *track.at(f / args.fps)) * unit * 1e3
                             for f in range(args.frames)] for name, run in runs.items() for first in (1, swing)}
    for f in range(args.frames):
        print(f"{f:5d} " + " ".join(f"{depth[key][f]:{w}.2f}" for key, w in zip(depth, (10, 8, 8, 8), strict=True)))
    for (name, first), d in depth.items():
        print(f"{name}, points {first}..{asset.cards.segments}: deepest {max(d):.2f} mm, mean over frames "
              f"{np.mean(d):.2f} mm, frames with a point inside {sum(x > 0 for x in d)} of {args.frames}")


if __name__ == "__main__":
    main()
