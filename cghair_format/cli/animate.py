"""``cgh animate IN.cgh -o OUT.cgh``: move a groom's cards, by the built-in simulation of a head motion
(``--motion``) or of the head's animated transform from a DCC tool (``--head-track HEAD.usd|.abc``), or
fitted to animated strands from a DCC tool (``--from ANIMATED.usd|.abc``), and write the frames as the
file's animation part; the rest pose stays as it was. A simulation collides with a sphere fitted to the
roots, or with the head mesh given as ``--collider MESH.obj|.ply|.usd``."""

from __future__ import annotations

import argparse
import time

from ..animation.track_file import RESTS
from ..animation.tracks import MOTIONS
from ..errors import CghError
from ..profiles import PROFILES
from .argtypes import int_at_least, positive_float, share


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="a .cgh file (its rest pose)")
    p.add_argument("-o", "--output", required=True, help="the animated .cgh to write")
    source = p.add_mutually_exclusive_group()
    source.add_argument("--motion", choices=MOTIONS, default=None,
                        help="simulate the hair on this head motion (default: nod)")
    source.add_argument("--from", dest="source", metavar="ANIMATED",
                        help="fit the cards to the animated strands of a USD (time-sampled curves) or Alembic file")
    source.add_argument("--head-track", metavar="HEAD",
                        help="simulate the hair on the animated transform of the head in a USD or Alembic file")
    p.add_argument("--head-prim", metavar="PATH",
                   help="with --head-track: the head's prim (default: the file's only animated xformable prim)")
    p.add_argument("--head-rest", choices=RESTS, default="first",
                   help="with --head-track: the .cgh holds the groom at the track's first frame (first, the "
                        "default) or in the head prim's own space (local)")
    p.add_argument("--collider", metavar="MESH",
                   help="collide with this head or scalp mesh (.obj, .ply, USD; in the .cgh's rest frame) instead "
                        "of a sphere fitted to the roots")
    p.add_argument("--refine", type=int_at_least(0), default=0,
                   help="with --from: Gauss-Newton steps on the exact card model after the linear fit (default 0)")
    p.add_argument("--frames", type=int_at_least(1), default=None,
                   help="frames to simulate (default 120; a head track's own)")
    p.add_argument("--fps", type=positive_float, default=None, help="frames a second (default 30; a head track's own)")
    p.add_argument("--substeps", type=int_at_least(1), default=None,
                   help="solver steps a frame (default 8); the hair moves alike at any count, more are finer")
    p.add_argument("--stiffness", type=share, default=None,
                   help="bend stiffness, 0..1: the pull toward each segment's rest bend a step, as on a strand of "
                        "32 points; converted per joint, so any point count bends alike (default 0.9)")
    p.add_argument("--damping", type=share, default=None,
                   help="velocity lost every 1/240 s, 0..1 (default 0.04), whatever the fps and substeps")
    p.add_argument("--wind", type=_vector, default=None, metavar="X,Y,Z", help="wind, m/s^2 across the strands")
    p.add_argument("--gust", type=share, default=0.0, help="strength of the seeded gusts, 0..1 (default 0)")
    p.add_argument("--seed", type=int, default=0, help="seed of the gusts (default 0)")
    p.add_argument("--profile", choices=list(PROFILES), default=None,
                   help="precision profile of the output (default: the input's)")


def _vector(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z (three numbers), got {text!r}") from None
    return x, y, z


def run(args: argparse.Namespace) -> int:
    from ..codec import read, read_info, write

    if args.source is not None and (args.motion is not None or args.wind is not None):
        raise CghError("--from takes its motion from the file: drop --motion and --wind")
    if args.source is not None and args.collider is not None:
        raise CghError("--from fits the cards to the file's strands, which collide as they were made: drop --collider")
    if args.head_track is not None and (args.frames is not None or args.fps is not None):
        raise CghError("--head-track takes its frames and frame rate from the file: drop --frames and --fps")
    if args.head_track is None and args.head_prim is not None:
        raise CghError("--head-prim names the head in a --head-track file: give one")
    asset, info = read(args.input), read_info(args.input)
    t = time.perf_counter()
    if args.source is not None:
        from ..animation.fit import animation_from_file, residual_lines

        animation, residuals = animation_from_file(asset, args.source, refine=args.refine)
        print("\n".join(residual_lines(residuals, animation.fps, animation.start)))
    else:
        animation = _simulated(asset, args)
    seconds = time.perf_counter() - t
    profile = _profile(args.profile, info)
    report = write(asset, args.output, profile, animation=animation)
    print(f"{animation.frames} frames at {animation.fps:g} fps ({animation.source}) in {seconds:.1f} s "
          f"({1e3 * seconds / animation.frames:.1f} ms a frame)")
    print(f"wrote {args.output}: {sum(report.chunk_sizes.values()):,} bytes of chunks, profile {report.profile}")
    print(report.animation.summary(report.bbox_diagonal))
    return 0


def _profile(name: str | None, info: dict):
    """``--profile``, else the input's: its named profile with the point bound it records (compact for a
    profile of the caller's own)."""
    if name is not None:
        return PROFILES[name]
    if info["profile"] not in PROFILES:
        return PROFILES["compact"]
    return PROFILES[info["profile"]].with_position_tolerance(info["quant"].get("position_tolerance"))


def _simulated(asset, args: argparse.Namespace):
    from dataclasses import replace

    from ..animation import SolverSettings, simulated_animation, tracked_animation

    changes = {"substeps": args.substeps, "local_stiffness": args.stiffness, "damping": args.damping,
               "wind": args.wind, "wind_gust": args.gust}
    settings = replace(SolverSettings(), **{k: v for k, v in changes.items() if v is not None})
    settings.check()
    field = _collider(asset, args.collider) if args.collider is not None else None
    if args.head_track is None:
        return simulated_animation(asset, args.motion or "nod", args.frames or 120, args.fps or 30.0, settings,
                                   args.seed, field)
    from pathlib import Path

    from ..animation.track_file import head_track_from_file

    track = head_track_from_file(args.head_track, asset, args.head_prim, args.head_rest)
    print(f"head track: {track.frames} frames at {track.fps:g} fps from {track.start:g} s")
    return tracked_animation(asset, track, settings, args.seed, field, f"simulate {Path(args.head_track).name}")


def _collider(asset, mesh: str):
    """The distance field of the ``--collider`` mesh, saying what it built and how long that took."""
    from ..animation.collider import collider_field

    t = time.perf_counter()
    field = collider_field(asset, mesh)
    shape = "x".join(map(str, field.distance.shape))
    print(f"collider {mesh}: a {shape} distance field of {field.cell:.4g}-unit cells in "
          f"{time.perf_counter() - t:.1f} s")
    return field
