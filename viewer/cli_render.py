"""``cgh render FILE.cgh -o out.png``: pictures and turntables without a display (EGL)."""

from __future__ import annotations

import argparse

from cghair_format.animation import MOTIONS

from .cli import add_raster_arguments, add_turn_argument

IMAGE_EXTS = (".png",)
ANIMATION_EXTS = (".gif", ".mp4")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="the .cgh file to render")
    parser.add_argument("-o", "--output", required=True, help="output .png, or .gif/.mp4 for --turntable")
    parser.add_argument("--width", type=int, default=None, help="image width (default 800, or transforms.json w)")
    parser.add_argument("--height", type=int, default=None, help="image height (default 800, or its h)")
    cam = parser.add_argument_group("orbit camera (default: framing the whole asset)")
    cam.add_argument("--azimuth", type=float, default=0.0, help="degrees about the up axis (default 0)")
    cam.add_argument("--elevation", type=float, default=10.0, help="degrees above the horizon (default 10)")
    cam.add_argument("--distance", type=float, default=None, help="from the target, scene units")
    cam.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                     help="point looked at (default: centre of the asset's bounds)")
    cam.add_argument("--fov", type=float, default=40.0, help="vertical field of view, degrees (default 40)")
    parser.add_argument("--camera", default=None, metavar="TRANSFORMS_JSON",
                        help="use a camera from a NeRF-style transforms.json instead of the orbit")
    parser.add_argument("--frame", type=int, default=0, help="frame index in --camera (default 0)")
    parser.add_argument("--turntable", type=int, default=0, metavar="N",
                        help="render N views around the up axis into an animated .gif or .mp4 (with --frames, "
                             "--animate or --motion: N images, the hair moving on a loop as the camera goes round)")
    parser.add_argument("--fps", type=float, default=None,
                        help="frame rate of the .gif/.mp4 (default: the animation's, or 24 for a turntable)")
    anim = parser.add_argument_group("hair that moves (one camera; .gif or .mp4)")
    anim.add_argument("--frames", default=None, metavar="A:B",
                      help="render frames A to B-1 of the file's animation (or of --motion), e.g. 0:48")
    anim.add_argument("--animate", action="store_true", help="render every frame of the animation")
    anim.add_argument("--motion", default=None, choices=MOTIONS,
                      help="simulate the hair under this built-in head motion (B frames of --frames, or 2 s) "
                           "instead of reading the file's animation")
    add_turn_argument(anim)
    look = parser.add_argument_group("appearance")
    look.add_argument("--background", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("R", "G", "B"))
    look.add_argument("--sh-degree", type=int, choices=(0, 1, 2, 3), default=None,
                      help="evaluate SH up to this degree (default: the file's)")
    look.add_argument("--splat-scale", type=float, default=1.0, help="multiply Gaussian scales (default 1)")
    look.add_argument("--color-by-group", action="store_true", help="colour splats by card group")
    look.add_argument("--cards", action="store_true", help="overlay the card strips")
    look.add_argument("--strands", action="store_true", help="overlay the strands as lines")
    parser.add_argument("--sort", choices=("auto", "gpu", "cpu"), default="auto", help="depth sort (default auto)")
    add_raster_arguments(parser, budget_help="draw at most N Gaussians (whole strands, compensated; e.g. 500k); "
                                             "default: all")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="say which OpenGL driver and device render (GL_RENDERER, GL_VENDOR, GL_VERSION)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import cghair_format
    from cghair_format.errors import CghError

    from .render_jobs import RenderJob, render_job

    out = Path(args.output)
    ext = out.suffix.lower()
    if ext not in IMAGE_EXTS + ANIMATION_EXTS:
        raise CghError(f"unsupported output {out.name!r}: use .png, or .gif/.mp4 with --turntable")
    if args.turntable < 0:
        raise CghError(f"--turntable must be >= 0, got {args.turntable}")
    if args.turntable and ext == ".png":
        raise CghError("--turntable writes an animation: name the output .gif or .mp4")
    if args.turntable and args.camera:
        raise CghError("--turntable orbits the asset: it cannot be combined with --camera")
    if not out.parent.exists():
        raise CghError(f"output folder {out.parent} does not exist")
    asset = cghair_format.read(args.file)
    animation, frames = _animation(args, asset)
    if frames is not None and ext == ".png":
        raise CghError("--frames, --animate and --motion write an animation: name the output .gif or .mp4")
    fps = args.fps if args.fps is not None else (animation.fps if frames is not None else 24.0)
    job = RenderJob(width=args.width, height=args.height, azimuth=args.azimuth, elevation=args.elevation,
                    distance=args.distance, target=args.target, fov=args.fov, transforms=args.camera,
                    frame=args.frame, turntable=args.turntable, fps=fps, background=tuple(args.background),
                    sh_degree=args.sh_degree, splat_scale=args.splat_scale,
                    color_by_group=args.color_by_group, cards=args.cards, strands=args.strands, sort=args.sort,
                    rasterizer=args.rasterizer, budget=args.budget, frames=frames, turn_sh=not args.no_turn_sh)
    written = render_job(asset, job, out, log=print if args.verbose else None, animation=animation)
    print(f"wrote {written}")
    return 0


def _animation(args: argparse.Namespace, asset):
    """The animation and the frames of it to render (``None, None``: the rest pose)."""
    from cghair_format.animation import simulated_animation
    from cghair_format.errors import CghError

    from .motion import file_animation, parse_frames

    if args.frames is None and not args.animate and args.motion is None:
        return None, None
    if args.frames is not None and args.animate:
        raise CghError("--animate renders every frame: leave out --frames, or --animate")
    if args.motion is not None:
        fps = 24.0 if args.fps is None else args.fps
        if not 0 < fps <= 1000:
            raise CghError(f"--fps must lie in (0, 1000], got {fps}")
        text = args.frames or ""
        try:  # enough frames for A:B (B of them) or N (N + 1); 2 s when B is left out
            end = text.rpartition(":")[2].strip()
            count = (int(end) if ":" in text else int(end) + 1) if end else round(2 * fps)
        except ValueError:
            raise CghError(f"--frames must be A:B or N (frame numbers), got {text!r}") from None
        if not 1 <= count <= 100_000:
            raise CghError(f"--motion simulates 1 to 100000 frames, got {count} (give --frames A:B with 0 < B)")
        animation = simulated_animation(asset, args.motion, count, fps)
    else:
        animation = file_animation(args.file)
        if animation is None:
            raise CghError(f"{args.file} holds no animation: make one with cgh animate, or name a built-in --motion")
    return animation, parse_frames(args.frames or ":", animation.frames)
