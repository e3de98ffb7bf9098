"""argparse value types shared by the verbs (argparse-level only: no heavy imports)."""

from __future__ import annotations

import argparse


def int_at_least(low: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, got {v}")
        return v
    return parse


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None


def positive_float(text: str) -> float:
    v = _number(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def non_negative_float(text: str) -> float:
    v = _number(text)
    if not 0 <= v < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text}")
    return v


def share(text: str) -> float:
    """A share in [0, 1)."""
    v = _number(text)
    if not 0 <= v < 1:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text}")
    return v


def point_tolerance(text: str) -> float:
    """A strand point bound as a fraction of the bounding-box diagonal, in (0, MAX_POSITION_TOLERANCE]."""
    from ..profiles import MAX_POSITION_TOLERANCE

    v = _number(text)
    if not 0 < v <= MAX_POSITION_TOLERANCE:
        raise argparse.ArgumentTypeError(f"must be a fraction of the bounding-box diagonal in (0, "
                                         f"{MAX_POSITION_TOLERANCE:g}] (compact 2e-4, high 2e-5), got {text}")
    return v


def add_point_tolerance_argument(p: argparse.ArgumentParser) -> None:
    """``--point-tolerance``, shared by the commands that write a quantized .cgh (cgh encode, cgh train)."""
    p.add_argument("--point-tolerance", type=point_tolerance, metavar="FRACTION",
                   help="hold the strand points within this fraction of their bounding-box diagonal instead of the "
                        "profile's (compact 2e-4, high 2e-5): looser is smaller, and the file records the bound "
                        "(quantized profiles only; docs/compression.md, 'Point tolerance')")


def with_point_tolerance(name: str, fraction: float | None):
    """The profile ``name`` with its points held within ``fraction`` of the bbox diagonal if given (a
    ``--point-tolerance``); a one-line ``CghError`` for the lossless profile."""
    from ..errors import CghError
    from ..profiles import get_profile

    try:
        return get_profile(name).with_position_tolerance(fraction)
    except ValueError as exc:
        raise CghError(f"--point-tolerance: {exc}") from None


def rgb(text: str) -> list[float]:
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be three numbers like 0,0,0, got {text!r}") from None
    if len(values) != 3 or not all(0 <= v <= 1 for v in values):
        raise argparse.ArgumentTypeError(f"must be three numbers in [0, 1] like 0,0,0, got {text!r}")
    return values
