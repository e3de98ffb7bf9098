"""The float-domain data model of a .cgh asset.

A :class:`HairAsset` holds what the paper stores, as plain numpy arrays:

- cards: per card a spine of ``M + 1`` points, a unit normal and a half-width at each spine point,
  and the card's codebook group; the strip mesh (vertices, triangles, UVs, normals) is derived from
  these (see :mod:`cghair_format.geometry` and spec section "Card strips");
- strands: each strand's card, and for each of its ``P`` points the card coordinates
  ``(u, v, delta)``: ``u`` along the card (0 at the root end, 1 at the tip end), ``v`` across it
  (0 on the left rail, 1 on the right), ``delta`` the displacement along the interpolated normal
  in scene units. The card triangle and barycentric coordinates follow from ``(u, v)``;
- one opacity per segment (one Gaussian per segment), the Gaussian thickness ``d``;
- optionally each strand's own point count ``n_s`` (2..P, spec 3, PCNT): the arrays keep ``P`` points
  per strand, and a strand with fewer has ``P - n_s`` trailing *placeholder* points (and segments) that
  are coded like any other and then dropped;
- appearance: per strand ``K`` logits, per card group a codebook of ``K`` latents of size ``D``, and
  one MLP from a latent to the SH coefficients of all ``P - 1`` Gaussians of a strand.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .errors import AssetError

UP_AXES = ("Y", "Z")
ACTIVATIONS = ("relu", "none")
MAX_MLP_VALUE = 1e30  # float32 reaches 3.4e38; a trained MLP stays many orders of magnitude below
# Lengths (card spines and widths, delta, the thickness) and card coordinates u, v stay below these, so that
# points, segment lengths and their squares stay finite in float32 (3.4e38): 1e12 scene units is a million
# km in metres, and the card builder's u, v lie within a few card widths of [0, 1]
MAX_LENGTH = 1e12
MAX_CARD_COORDINATE = 1e3
WEIGHT_MODES = ("soft", "hard")


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise AssetError(message)


def _check_array(name: str, a: np.ndarray, shape: tuple, kind: str, bound: float | None = None) -> None:
    _check(isinstance(a, np.ndarray), f"{name} must be a numpy array, got {type(a).__name__}")
    _check(a.ndim == len(shape), f"{name} must have {len(shape)} dimensions, got shape {a.shape}")
    for axis, (want, got) in enumerate(zip(shape, a.shape, strict=True)):
        _check(want is None or want == got, f"{name} axis {axis} must be {want}, got shape {a.shape}")
    _check(a.dtype.kind in kind, f"{name} has dtype {a.dtype}, expected kind {kind!r}")
    if a.dtype.kind == "f":
        _check(bool(np.isfinite(a).all()), f"{name} contains NaN or infinite values")
        if bound is not None and a.size:
            _check(float(np.abs(a).max()) <= bound, f"{name} holds values beyond +-{bound:g}")


@dataclass
class Cards:
    """Hair cards: ``C`` strips of ``M`` segments each."""

    spine: np.ndarray  # [C, M+1, 3] float32, spine (guide) points
    normal: np.ndarray  # [C, M+1, 3] float32, unit card normals, orthogonal to the spine tangent
    half_width: np.ndarray  # [C, M+1] float32, >= 0, distance from the spine to each rail
    group: np.ndarray  # [C] int32, codebook group of the card, in [0, N_T)

    @property
    def count(self) -> int:
        return int(self.spine.shape[0])

    @property
    def segments(self) -> int:
        return int(self.spine.shape[1]) - 1

    def validate(self, n_groups: int) -> None:
        c, m1 = self.spine.shape[:2] if self.spine.ndim == 3 else (-1, -1)
        _check_array("cards.spine", self.spine, (None, None, 3), "f", MAX_LENGTH)
        _check(c >= 1 and m1 >= 2, f"cards need at least 1 card of 1 segment, got spine shape {self.spine.shape}")
        _check_array("cards.normal", self.normal, (c, m1, 3), "f")
        _check_array("cards.half_width", self.half_width, (c, m1), "f", MAX_LENGTH)
        _check_array("cards.group", self.group, (c,), "iu")
        _check(bool((self.half_width >= 0).all()), "cards.half_width must be >= 0")
        norms = np.linalg.norm(self.normal.astype(np.float64), axis=-1)  # float64: a float32's square fits
        _check(bool((np.abs(norms - 1) < 1e-3).all()), "cards.normal must be unit vectors")
        _check(bool(((self.group >= 0) & (self.group < n_groups)).all()),
               f"cards.group must lie in [0, {n_groups})")


@dataclass
class MlpLayer:
    weight: np.ndarray  # [out, in] float32
    bias: np.ndarray  # [out] float32
    activation: str = "relu"  # applied after this layer: "relu" or "none"


@dataclass
class Appearance:
    """The compact appearance model: codebooks, per-strand logits and the global MLP."""

    logits: np.ndarray  # [S, K] float32
    codebooks: np.ndarray  # [N_T, K, D] float32
    mlp: list[MlpLayer]  # input D, output (P-1) * (sh_degree+1)^2 * 3
    sh_degree: int = 3
    weight_mode: str = "soft"  # "soft": softmax(logits / temperature); "hard": one-hot argmax
    temperature: float = 1.0

    @property
    def n_groups(self) -> int:
        return int(self.codebooks.shape[0])

    @property
    def k(self) -> int:
        return int(self.codebooks.shape[1])

    @property
    def latent_dim(self) -> int:
        return int(self.codebooks.shape[2])

    @property
    def sh_coeffs(self) -> int:
        return (self.sh_degree + 1) ** 2

    def validate(self, n_strands: int, n_segments: int) -> None:
        _check_array("appearance.codebooks", self.codebooks, (None, None, None), "f")
        n_t, k, d = self.codebooks.shape
        _check(n_t >= 1 and k >= 1 and d >= 1, f"codebooks must be non-empty, got {self.codebooks.shape}")
        _check_array("appearance.logits", self.logits, (n_strands, k), "f")
        _check(0 <= self.sh_degree <= 3, f"sh_degree must be 0..3, got {self.sh_degree}")
        _check(self.weight_mode in WEIGHT_MODES, f"weight_mode must be one of {WEIGHT_MODES}")
        _check(np.isfinite(self.temperature) and self.temperature > 0, "temperature must be > 0")
        _check(len(self.mlp) >= 1, "the MLP needs at least one layer")
        width = d
        for i, layer in enumerate(self.mlp):
            _check_array(f"mlp[{i}].weight", layer.weight, (None, width), "f")
            _check_array(f"mlp[{i}].bias", layer.bias, (layer.weight.shape[0],), "f")
            _check(layer.activation in ACTIVATIONS, f"mlp[{i}].activation must be one of {ACTIVATIONS}")
            width = layer.weight.shape[0]
        want = n_segments * self.sh_coeffs * 3
        _check(width == want, f"the MLP outputs {width} values; {n_segments} Gaussians x "
               f"{self.sh_coeffs} SH coefficients x 3 channels need {want}")
        # a latent is a convex mix of codebook rows, and relu (or none) never grows a value: bound each
        # layer's outputs, so that decoding to Gaussians in float32 cannot overflow
        bound = float(np.abs(self.codebooks).max())
        for i, layer in enumerate(self.mlp):
            bound = (float(np.abs(layer.weight.astype(np.float64)).sum(axis=1).max()) * bound
                     + float(np.abs(layer.bias.astype(np.float64)).max()))
            _check(bound <= MAX_MLP_VALUE, f"mlp[{i}] could output values up to {bound:.3g}, beyond float32's "
                   f"safe range ({MAX_MLP_VALUE:g}): its weights or biases are far outside any trained model's")


@dataclass
class HairAsset:
    """Everything a .cgh file stores, as float arrays. See the module docstring."""

    cards: Cards
    strand_card: np.ndarray  # [S] int32, card of each strand
    uvd: np.ndarray  # [S, P, 3] float32, (u, v, delta) of each strand point on its card
    opacity: np.ndarray  # [S, P-1] float32 in [0, 1], one per segment Gaussian
    appearance: Appearance
    thickness: float = 1e-4  # Gaussian radius d, scene units
    meters_per_unit: float = 1.0
    up_axis: str = "Y"
    generator: str = "cghair"
    attribution: str = ""
    strand_ids: np.ndarray | None = None  # [S] uint32, optional
    root_uv: np.ndarray | None = None  # [S, 2] float32, optional scalp coordinates of each root
    source_color: np.ndarray | None = None  # [S, P, 3] float32 in [0, 1], optional
    metadata: dict = field(default_factory=dict)  # optional free-form JSON-able data
    point_counts: np.ndarray | None = None  # [S] int32 in 2..P, each strand's own points (None: all P)

    @property
    def n_strands(self) -> int:
        return int(self.uvd.shape[0])

    @property
    def points_per_strand(self) -> int:
        """``P``: the points every per-point array holds per strand (the largest count, placeholders after
        a shorter strand's own points)."""
        return int(self.uvd.shape[1])

    @property
    def variable(self) -> bool:
        """Whether some strand has fewer than ``P`` points (a file stores PCNT, spec 3)."""
        return self.point_counts is not None and bool((self.point_counts < self.points_per_strand).any())

    @property
    def counts(self) -> np.ndarray:
        """Each strand's own point count ``[S]`` (int64), ``P`` for all where none are given."""
        if self.point_counts is None:
            return np.full(self.n_strands, self.points_per_strand, np.int64)
        return self.point_counts.astype(np.int64)

    @property
    def n_gaussians(self) -> int:
        """One Gaussian per real segment: ``sum(n_s - 1)``."""
        return int((self.counts - 1).sum())

    def real_points(self) -> np.ndarray:
        """``[S, P]`` bool: the strands' own points, not placeholders."""
        return np.arange(self.points_per_strand)[None, :] < self.counts[:, None]

    def real_segments(self) -> np.ndarray:
        """``[S, P-1]`` bool: the strands' own segments (Gaussians), not placeholders."""
        return np.arange(self.points_per_strand - 1)[None, :] < self.counts[:, None] - 1

    def with_placeholders(self) -> HairAsset:
        """The same asset with every placeholder the cheapest to code: a copy of its strand's last own
        point's coordinates, opacity and colour (a decoder drops them; constant runs predict exactly)."""
        if not self.variable:
            return self
        last = self.counts - 1
        rows = np.arange(self.n_strands)[:, None]
        point = np.minimum(np.arange(self.points_per_strand)[None, :], last[:, None])
        segment = np.minimum(np.arange(self.points_per_strand - 1)[None, :], last[:, None] - 1)
        color = None if self.source_color is None else self.source_color[rows, point]
        return replace(self, uvd=self.uvd[rows, point], opacity=self.opacity[rows, segment], source_color=color)

    def take_strands(self, order: np.ndarray) -> HairAsset:
        """The same asset with its strands in ``order`` (indices into the strands): every per-strand
        array follows; cards, codebooks and MLP are shared."""
        order = np.asarray(order, np.int64)

        def pick(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[order]

        app = self.appearance
        return replace(self, strand_card=self.strand_card[order], uvd=self.uvd[order], opacity=self.opacity[order],
                       appearance=replace(app, logits=app.logits[order]), strand_ids=pick(self.strand_ids),
                       root_uv=pick(self.root_uv), source_color=pick(self.source_color),
                       point_counts=pick(self.point_counts))

    def validate(self) -> HairAsset:
        """Check shapes, dtypes, ranges and cross-references; raise :class:`AssetError` if wrong."""
        _check(isinstance(self.cards, Cards), "cards must be a Cards")
        _check(isinstance(self.appearance, Appearance), "appearance must be an Appearance")
        self.cards.validate(self.appearance.n_groups if self.appearance.codebooks.ndim == 3 else 0)
        _check_array("uvd", self.uvd, (None, None, 3), "f")
        s, p = self.uvd.shape[:2]
        if self.uvd.ndim == 3 and self.uvd.size:
            _check(float(np.abs(self.uvd[..., :2]).max()) <= MAX_CARD_COORDINATE,
                   f"uvd holds card coordinates u, v beyond +-{MAX_CARD_COORDINATE:g}")
            _check(float(np.abs(self.uvd[..., 2]).max()) <= MAX_LENGTH, f"uvd holds a delta beyond +-{MAX_LENGTH:g}")
        _check(s >= 1 and p >= 2, f"need at least 1 strand of 2 points, got uvd shape {self.uvd.shape}")
        _check_array("strand_card", self.strand_card, (s,), "iu")
        _check(bool(((self.strand_card >= 0) & (self.strand_card < self.cards.count)).all()),
               f"strand_card must lie in [0, {self.cards.count})")
        _check_array("opacity", self.opacity, (s, p - 1), "f")
        _check(bool(((self.opacity >= 0) & (self.opacity <= 1)).all()), "opacity must lie in [0, 1]")
        self.appearance.validate(s, p - 1)
        _check(np.isfinite(self.thickness) and 0 < self.thickness <= MAX_LENGTH,
               f"thickness must be > 0 and at most {MAX_LENGTH:g}, got {self.thickness}")
        _check(np.isfinite(self.meters_per_unit) and self.meters_per_unit > 0, "meters_per_unit must be > 0")
        _check(self.up_axis in UP_AXES, f"up_axis must be one of {UP_AXES}")
        if self.strand_ids is not None:
            _check_array("strand_ids", self.strand_ids, (s,), "iu")
        if self.root_uv is not None:
            _check_array("root_uv", self.root_uv, (s, 2), "f")
        if self.source_color is not None:
            _check_array("source_color", self.source_color, (s, p, 3), "f")
        if self.point_counts is not None:
            _check_array("point_counts", self.point_counts, (s,), "iu")
            _check(bool(((self.point_counts >= 2) & (self.point_counts <= p)).all()),
                   f"point_counts must lie in [2, {p}] (the points per strand)")
        _check(_finite_json(self.metadata), "metadata must be JSON of finite numbers")
        return self


def _finite_json(value) -> bool:
    """Whether ``value`` is JSON data with no NaN or infinite number (which JSON cannot write)."""
    if isinstance(value, float):
        return bool(np.isfinite(value))
    if isinstance(value, dict):
        return all(isinstance(k, str) and _finite_json(v) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return all(_finite_json(v) for v in value)
    return value is None or isinstance(value, (str, int, bool))
