"""The card builder: strands -> cards, card coordinates and a default appearance (a HairAsset)."""

from __future__ import annotations

import io
import sys
from dataclasses import dataclass, field

import numpy as np

from ..asset import Cards, HairAsset
from ..errors import CghError, require
from ..gaussians import decode_strands
from ..strands import Strands
from ..strands import resample as resample_strands
from . import appearance as app
from ._util import timed
from .cluster import cluster_strands
from .guide import guide_spines
from .inverse import STRIP_TOLERANCE, fit_strip
from .normals import card_half_widths, card_normals
from .textures import card_groups, strand_textures

# One BLAS/OpenMP thread: k-means results then do not depend on the thread count (summation order),
# and on a shared, loaded machine scikit-learn's multi-threaded k-means spins, many times slower than
# one thread (docs/format.md, "Card builder").
BUILD_THREADS = 1
DEFAULT_SEGMENTS = 32  # M: 33 spine points per card; with P = 100 about 3 strand points per segment
STAGES = ("resample", "cluster", "guide", "normals", "uv", "textures", "appearance", "verify")


class CardBuildError(CghError, ValueError):
    """The card builder cannot work on these strands or options."""


@dataclass
class ReconstructionError:
    """Point error of decoded strands against the input's points (or their resampling)."""

    mean_abs: float
    max_abs: float
    bbox_diagonal: float

    @property
    def mean_rel(self) -> float:
        return self.mean_abs / self.bbox_diagonal if self.bbox_diagonal > 0 else 0.0

    @property
    def max_rel(self) -> float:
        return self.max_abs / self.bbox_diagonal if self.bbox_diagonal > 0 else 0.0

    @classmethod
    def measure(cls, reference: np.ndarray, decoded: np.ndarray) -> ReconstructionError:
        """The error of ``decoded`` points against ``reference`` (the same points, any shape ``[..., 3]``)."""
        ref = reference.reshape(-1, 3).astype(np.float64)
        err = np.linalg.norm(decoded.reshape(-1, 3).astype(np.float64) - ref, axis=-1)
        diag = float(np.linalg.norm(ref.max(0) - ref.min(0)))
        return cls(float(err.mean()), float(err.max()), diag)

    def line(self, label: str) -> str:
        return (f"{label}: mean {self.mean_abs:.3g} ({self.mean_rel:.2e} of bbox diagonal), "
                f"max {self.max_abs:.3g} ({self.max_rel:.2e})")


@dataclass(frozen=True)
class Resampling:
    """How the card builder changed the input's points: from ``min_points``-``max_points`` a strand
    to ``points``, moving input points up to ``shape_error`` (of the bbox diagonal) off the shape."""

    min_points: int
    max_points: int
    points: int
    shape_error: float  # max distance of an input point from its resampled polyline / bbox diagonal

    def line(self) -> str:
        given = str(self.min_points) if self.min_points == self.max_points else f"{self.min_points}-{self.max_points}"
        return (f"strands resampled from {given} to {self.points} points along their arc length: input points lie "
                f"up to {self.shape_error:.2e} of the bbox diagonal off the resampled shape")


@dataclass
class CardBuild:
    """The result of :func:`build_cards`."""

    asset: HairAsset  # validated, with the default appearance (point_counts: the input's, where they vary)
    timings: dict[str, float]  # seconds per stage, in STAGES order
    error: ReconstructionError  # decoded (float, before quantization) vs the points below
    # [S, P, 3] float32, the input's points (or their resampling) the error refers to; a strand with fewer
    # than P (asset.point_counts) repeats its last point after its own
    points: np.ndarray
    textures: np.ndarray  # [C, T, T] float32 strand coverage images, rows along u
    colors: np.ndarray | None = None  # [S, P, 3] float32 input colours (as the points), if the input has them
    strip_rounds: int = 0  # widen / extend rounds used by the inverse UV mapping
    unsolved_points: int = 0  # points without an exact card solution (kept at nearest-spine coords)
    outside_strip: int = 0  # points with v outside [0, 1] (beyond the tolerance)
    info: dict = field(default_factory=dict)
    resampling: Resampling | None = None  # None: the input's own points were kept

    def quantized_error(self, profile: str = "compact") -> tuple[ReconstructionError, int]:
        """Error after encoding with ``profile`` and decoding, and the encoded size in bytes."""
        from ..codec import decode, encode

        data, report = encode(self.asset, profile)
        return self.error_of(decode(data), report), len(data)

    def error_of(self, decoded: HairAsset, report) -> ReconstructionError:
        """The point error of ``decoded``, the asset written with ``report`` (an ``EncodeReport``: its
        strand order) and read back, against the points the build kept."""
        reference = own_points(report.strands_in_file_order(self.points),
                               report.strands_in_file_order(self.asset.counts))
        return ReconstructionError.measure(reference, decode_strands(decoded).points)

    def timing_table(self) -> str:
        out = io.StringIO()
        out.write(f"{'stage':<12}{'seconds':>10}\n")
        for stage in STAGES:
            if stage in self.timings:
                out.write(f"{stage:<12}{self.timings[stage]:>10.2f}\n")
        out.write(f"{'total':<12}{sum(self.timings.values()):>10.2f}\n")
        return out.getvalue()


def _check_options(strands: Strands, n_cards: int, n_groups: int, segments: int, points: int,
                   sh_degree: int) -> None:
    if not isinstance(strands, Strands):
        raise CardBuildError(f"build_cards needs Strands, got {type(strands).__name__}")
    strands.validate()
    if strands.count < 1:
        raise CardBuildError("no strands to build cards from")
    if (strands.point_counts < 1).any():
        raise CardBuildError(f"{int((strands.point_counts < 1).sum())} strands have no points")
    for name, value, low in (("n_cards", n_cards, 1), ("n_groups", n_groups, 1), ("segments", segments, 1),
                             ("points", points, 4)):
        if int(value) != value or value < low:
            raise CardBuildError(f"{name} must be an integer >= {low}, got {value}")
    if segments > 4096 or points > 100000:
        raise CardBuildError(f"segments ({segments}) or points ({points}) is unreasonably large")
    if sh_degree not in (0, 1, 2, 3):
        raise CardBuildError(f"sh_degree must be 0..3, got {sh_degree}")


def own_points(points: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Each strand's first ``counts`` entries of ``points [S, P, ...]``, flat ``[sum(counts), ...]``."""
    return points[np.arange(points.shape[1])[None, :] < counts[:, None]]


def _padded(flat: np.ndarray, offsets: np.ndarray, p: int) -> np.ndarray:
    """Flat per-point values ``[N, ...]`` of strands (``offsets``) as ``[S, p, ...]``, a strand with fewer
    than ``p`` points repeating its last (the writer's placeholders, spec 3)."""
    counts = np.diff(offsets)
    return flat[offsets[:-1, None] + np.minimum(np.arange(p)[None, :], counts[:, None] - 1)]


def resample(strands: Strands, points: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Points ``[S, P, 3]`` (float64), colours ``[S, P, 3]`` and widths ``[S, P]`` (or None): the
    input's own points when every strand has ``points`` of them, else every strand resampled to
    ``points`` points evenly spaced along its arc length."""
    out = strands if (strands.point_counts == points).all() else resample_strands(strands, points)
    s = out.count
    colors = None if out.colors is None else out.colors.reshape(s, points, 3).astype(np.float64).clip(0, 1)
    widths = None if out.widths is None else out.widths.reshape(s, points).astype(np.float64)
    return out.to_array().astype(np.float64), colors, widths


def shape_error(strands: Strands, resampled: np.ndarray) -> float:
    """Largest distance from an input point to its strand's resampled polyline ``[S, P, 3]``: how far
    resampling moved the shape the user gave (0 when the points were kept)."""
    worst = 0.0
    a, b = resampled[:, :-1], resampled[:, 1:]  # [S, P-1, 3] segments
    counts = strands.point_counts
    for start in range(0, strands.count, 512):  # bounded memory: 512 strands at a time
        stop = min(strands.count, start + 512)
        owner = np.repeat(np.arange(start, stop), counts[start:stop])
        pts = strands.points[strands.offsets[start]:strands.offsets[stop]].astype(np.float64)
        seg_a, seg_d = a[owner], b[owner] - a[owner]  # [n, P-1, 3]
        t = np.einsum("nkc,nkc->nk", pts[:, None] - seg_a, seg_d) / np.maximum(
            np.einsum("nkc,nkc->nk", seg_d, seg_d), 1e-300)
        near = seg_a + np.clip(t, 0, 1)[..., None] * seg_d
        worst = max(worst, float(np.sqrt(((near - pts[:, None]) ** 2).sum(-1).min(1).max())))
    return worst


def _carry_by_arc_length(s_even: np.ndarray, flat: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Spine parameters ``[N]`` of the strands' points ``flat [N, 3]`` (strand ``i`` is
    ``flat[offsets[i]:offsets[i+1]]``, any count) from those ``s_even [S, P]`` of the same strands' ``P``
    evenly spaced points, interpolated at each point's fraction of its strand's arc length."""
    counts = np.diff(offsets)
    pts = _padded(flat, offsets, int(counts.max()))  # a shorter strand's repeated last point adds no length
    seg = np.sqrt((np.diff(pts, axis=1) ** 2).sum(-1))
    arc = np.concatenate([np.zeros((len(pts), 1)), np.cumsum(seg, 1)], 1)
    p = s_even.shape[1]
    pos = arc / np.maximum(arc[:, -1:], 1e-300) * (p - 1)  # in units of the even spacing
    lo = np.clip(np.floor(pos).astype(np.int64), 0, p - 2)
    w = pos - lo
    rows = np.arange(len(pts))[:, None]
    carried = s_even[rows, lo] * (1 - w) + s_even[rows, lo + 1] * w
    return carried[np.arange(pts.shape[1])[None, :] < counts[:, None]]


def default_points(strands: Strands) -> int:
    """``P``, the points per strand the builder stores: the largest count. Every strand keeps its own
    points (a strand with fewer is stored with its own count, spec 3) unless one has a single point."""
    return int(strands.point_counts.max())


def build_cards(strands: Strands, n_cards: int = 800, n_groups: int = 64, segments: int = DEFAULT_SEGMENTS,
                points: int | None = None, seed: int = 0, progress: bool = True, *, sh_degree: int = 3,
                log=None) -> CardBuild:
    """Build the cards of ``strands`` and return a :class:`CardBuild` (asset, timings, error).

    ``points`` (default None: every strand keeps its own points, ``P`` :func:`default_points`, and a
    strand with fewer is stored with its own count) resamples every strand to ``points`` points along
    its arc length, unless all have that many already; ``CardBuild.resampling`` then says how far that
    moved them (a strand of one point is resampled to ``P`` too). ``n_cards`` and
    ``n_groups`` are capped at the strand and card counts. The result depends only on the inputs and
    ``seed``. ``log`` (a text stream, default stderr when ``progress``) receives one line per
    finished stage.
    """
    keep = points is None
    if isinstance(strands, Strands) and points is None and strands.count:
        points = default_points(strands)
    _check_options(strands, n_cards, n_groups, segments, 4 if points is None else points, sh_degree)
    keep = (keep and bool((strands.point_counts >= 2).all())) or bool((strands.point_counts == points).all())
    threadpoolctl = require("threadpoolctl", "cards", "the card builder")
    with threadpoolctl.threadpool_limits(limits=BUILD_THREADS):
        return _build(strands, n_cards, n_groups, segments, points, keep, seed, progress, sh_degree, log)


@dataclass
class _Points:
    """The strands' points as the build's stages see them (each array float64)."""

    flat: np.ndarray  # [N, 3] the points stored: each strand's own count, or P after resampling
    offsets: np.ndarray  # [S + 1] strand i is flat[offsets[i]:offsets[i + 1]]
    shape: np.ndarray  # [S, P, 3] evenly spaced along each strand: what k-means and the guides compare
    padded: np.ndarray  # [S, P, 3] the stored points, a shorter strand repeating its last
    colors: np.ndarray | None  # [S, P, 3] as ``padded``
    looks: tuple  # (points, colours, widths) [S, P, ...] the default appearance is read from
    diag: float  # the bbox diagonal of ``flat``
    resampling: Resampling | None  # None: the input's own points were kept


def _prepare_points(strands: Strands, points: int, keep: bool) -> _Points:
    """The stage "resample": the input's own points (``keep``) or every strand resampled to ``points``."""
    if keep:
        # k-means and the guides compare strands point by point, so they see evenly spaced points;
        # the normals, widths and stored points are the user's own, of each strand's own count
        offsets = strands.offsets
        flat = strands.points.astype(np.float64)
        even = resample_strands(strands, points)
        shape = even.to_array().astype(np.float64)
        pts = _padded(flat, offsets, points)
        colors = None if strands.colors is None else _padded(strands.colors.astype(np.float64).clip(0, 1),
                                                              offsets, points)
        variable = bool((strands.point_counts < points).any())
        # a shorter strand's repeated last point would skew the root / tip colours and the mid points
        looks = (resample(even, points) if variable else
                 (pts, colors, None if strands.widths is None else _padded(strands.widths, offsets, points)))
    else:
        pts, colors, widths = resample(strands, points)
        offsets = np.arange(strands.count + 1, dtype=np.int64) * points
        flat, shape = pts.reshape(-1, 3), pts
        looks = (pts, colors, widths)
    diag = float(np.linalg.norm(flat.max(0) - flat.min(0)))
    if not diag > 0:
        raise CardBuildError("all strand points coincide: nothing to build cards from")
    resampling = None
    if not keep:
        counts = strands.point_counts
        resampling = Resampling(int(counts.min()), int(counts.max()), int(points), shape_error(strands, pts) / diag)
    return _Points(flat, offsets, shape, pts, colors, looks, diag, resampling)


def _build(strands: Strands, n_cards: int, n_groups: int, segments: int, points: int, keep: bool, seed: int,
           progress: bool, sh_degree: int, log) -> CardBuild:
    log = log if log is not None else (sys.stderr if progress else None)
    timings: dict[str, float] = {}

    def done(stage: str) -> None:
        if log is not None:
            print(f"cards: {stage:<11}{timings[stage]:8.2f} s", file=log, flush=True)

    s_count = strands.count
    with timed(timings, "resample"):
        p = _prepare_points(strands, points, keep)
        flat, offsets = p.flat, p.offsets
        counts = np.diff(offsets)
    done("resample")

    with timed(timings, "cluster"):
        labels = cluster_strands(p.shape, n_cards, seed)
        c = int(labels.max()) + 1
    done("cluster")

    with timed(timings, "guide"):
        spine, s = guide_spines(p.shape, labels, c, segments, show_progress=progress)
        if keep:
            s = _carry_by_arc_length(s.reshape(s_count, points), flat, offsets)
    done("guide")

    point_card = np.repeat(labels, counts)
    with timed(timings, "normals"):
        normal = card_normals(spine, flat, point_card, s, hair_centre=flat[offsets[:-1]].mean(0),
                              show_progress=progress)
        half = card_half_widths(spine, normal, flat, point_card, s, p.diag)
        cards = Cards(spine.astype(np.float32), normal.astype(np.float32), half.astype(np.float32),
                      np.zeros(c, np.int32))
    done("normals")

    with timed(timings, "uv"):
        cards, uvd, solved, rounds = fit_strip(cards, flat, point_card, s, show_progress=progress)
        uvd = _padded(uvd, offsets, points).astype(np.float32)
    done("uv")

    with timed(timings, "textures"):
        textures = strand_textures(uvd[..., :2], labels, c, counts=np.diff(offsets))
        groups = card_groups(textures, n_groups, seed)
        cards.group = groups
        n_t = int(groups.max()) + 1
    done("textures")

    with timed(timings, "appearance"):
        look_points, look_colors, look_widths = p.looks
        profiles = app.colour_profiles(look_colors, s_count, seed)
        appearance = app.default_appearance(profiles, groups[labels], n_t, points, sh_degree, seed)
        asset = HairAsset(
            cards=cards, strand_card=labels.astype(np.int32), uvd=uvd,
            opacity=app.default_opacity(s_count, points), appearance=appearance,
            thickness=app.default_thickness(look_points, look_widths), meters_per_unit=float(strands.meters_per_unit),
            up_axis=strands.up_axis, generator="cghair cards",
            metadata={"cards": {"seed": int(seed), "segments": int(segments), "points": int(points),
                                "requested_cards": int(n_cards), "requested_groups": int(n_groups)}},
            point_counts=counts.astype(np.int32) if (counts < points).any() else None,
        ).validate()
    done("appearance")

    with timed(timings, "verify"):
        error = ReconstructionError.measure(flat, decode_strands(asset).points)
        v = uvd[..., 1]
        outside = int(((v < -STRIP_TOLERANCE) | (v > 1 + STRIP_TOLERANCE)).sum())
    done("verify")
    return CardBuild(asset=asset, timings=timings, error=error, points=p.padded.astype(np.float32),
                     textures=textures, colors=None if p.colors is None else p.colors.astype(np.float32),
                     strip_rounds=rounds, unsolved_points=int((~solved).sum()),
                     outside_strip=outside, resampling=p.resampling,
                     info={"cards": c, "groups": n_t, "strands": s_count, "points": points})
