"""Built-in procedural hairstyles: strands grown from a head-shaped scalp, with hair colour.

The head is an ellipsoid (metres, y up, face towards +z). Roots are spread over its upper and
back part (hairline above the forehead and ears). Each strand grows along the scalp normal and
bends under gravity; curls are helices around that centre line; every point that would enter
the head is pushed back out, so no strand intersects it. Colour follows a melanin model: each
strand's eumelanin/pheomelanin concentration varies around the head's, and ``multitone`` adds
lighter dyed tips and contrasting streaks (the hardest appearance case of the paper).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import AssetError
from .strands import Strands

HEAD_CENTER = np.array([0.0, 0.0, 0.0])
HEAD_RADII = np.array([0.075, 0.10, 0.095])  # half width (x), half height (y), half depth (z)
SCALP_MARGIN = 1.03  # strands stay outside the head scaled by this factor
HAIR_WIDTH = 7e-5  # metres, a typical hair diameter
# absorption per unit concentration of eumelanin and pheomelanin (d'Eon et al. 2011)
EUMELANIN = np.array([0.419, 0.697, 1.37])
PHEOMELANIN = np.array([0.187, 0.4, 1.05])


@dataclass(frozen=True)
class Style:
    length: float  # metres, mean strand length
    stiffness: float  # metres of growth before gravity dominates
    curl_radius: float  # helix radius (0: none)
    curl_period: float  # metres of strand per helix turn
    wave: bool = False  # planar wave instead of a helix
    ponytail: bool = False


STYLES: dict[str, Style] = {
    "straight": Style(0.35, 0.012, 0.0, 1.0),
    "wavy": Style(0.35, 0.012, 0.012, 0.07, wave=True),
    "curly": Style(0.28, 0.04, 0.010, 0.035),
    "coily": Style(0.18, 0.06, 0.005, 0.010),
    "short": Style(0.06, 0.05, 0.0, 1.0),
    "long": Style(0.60, 0.012, 0.0, 1.0),
    "ponytail": Style(0.45, 0.02, 0.0, 1.0, ponytail=True),
}
PONYTAIL_TIE = np.array([0.0, 0.03, -0.105])


def _scalp_roots(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` roots on the ellipsoid's scalp region and their outward unit normals."""
    dirs = np.empty((0, 3))
    while len(dirs) < n:
        d = rng.normal(size=(2 * n + 64, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        front = d[:, 2]
        # hairline: high on the forehead, down to the nape at the back, above the ears at the sides
        limit = np.where(front > 0, 0.15 + 0.45 * front, -0.35 - 0.2 * np.abs(front))
        limit = np.where(np.abs(d[:, 0]) > 0.8, np.maximum(limit, 0.05), limit)
        dirs = np.concatenate([dirs, d[d[:, 1] > limit]])
    dirs = dirs[:n]
    # uniform directions map to non-uniform ellipsoid area; good enough for a scalp
    roots = HEAD_CENTER + dirs * HEAD_RADII * SCALP_MARGIN
    normals = (roots - HEAD_CENTER) / HEAD_RADII ** 2
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return roots, normals


def push_out_of_head(points: np.ndarray, margin: float = SCALP_MARGIN) -> np.ndarray:
    """Move every point inside the ellipsoid scaled by ``margin`` radially onto its surface."""
    rel = (points - HEAD_CENTER) / HEAD_RADII
    f = np.linalg.norm(rel, axis=-1, keepdims=True)
    inside = f < margin
    scale = np.where(inside, margin / np.maximum(f, 1e-9), 1.0)
    return np.where(inside, HEAD_CENTER + (points - HEAD_CENTER) * scale, points)


def inside_head(points: np.ndarray) -> np.ndarray:
    """True where a point lies strictly inside the head ellipsoid."""
    return np.linalg.norm((points - HEAD_CENTER) / HEAD_RADII, axis=-1) < 1.0


def _grow(roots: np.ndarray, normals: np.ndarray, lengths: np.ndarray, n_points: int, style: Style,
          rng: np.random.Generator) -> np.ndarray:
    """Centre lines ``[S, P, 3]``: growth along the normal bending to gravity (or to the tie)."""
    s = len(roots)
    step = lengths / (n_points - 1)
    pts = np.empty((s, n_points, 3))
    pts[:, 0] = roots
    d = normals.copy()
    gravity = np.array([0.0, -1.0, 0.0])
    jitter = rng.normal(0, 0.15, (s, 3))
    grown = np.zeros(s)
    for k in range(1, n_points):
        grown += step
        if style.ponytail:
            to_tie = PONYTAIL_TIE - pts[:, k - 1]
            dist = np.linalg.norm(to_tie, axis=1, keepdims=True)
            tied = dist < 0.01
            target = np.where(tied | (grown[:, None] > 0.25), gravity + 0.1 * jitter,
                              to_tie / np.maximum(dist, 1e-9))
            blend = 0.35
        else:
            target = gravity + 0.25 * jitter
            blend = 1 - np.exp(-step / style.stiffness)[:, None]
        d = (1 - blend) * d + blend * target
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        nxt = pts[:, k - 1] + d * step[:, None]
        nxt = push_out_of_head(nxt)
        pts[:, k] = nxt
        # re-derive the direction after a push, so strands slide along the scalp
        moved = nxt - pts[:, k - 1]
        norm = np.linalg.norm(moved, axis=1, keepdims=True)
        d = np.where(norm > 1e-12, moved / np.maximum(norm, 1e-12), d)
    return pts


def _curl(pts: np.ndarray, style: Style, rng: np.random.Generator) -> np.ndarray:
    """Add a helix (or planar wave) around each centre line, fading in over the first 2 cm."""
    if style.curl_radius <= 0:
        return pts
    s, p = pts.shape[:2]
    seg = np.linalg.norm(np.diff(pts, axis=1), axis=-1)
    arc = np.concatenate([np.zeros((s, 1)), np.cumsum(seg, axis=1)], axis=1)
    t = np.gradient(pts, axis=1)
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-12)
    ref = np.where(np.abs(t[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    u = np.cross(t, ref)
    u /= np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-12)
    v = np.cross(t, u)
    radius = style.curl_radius * rng.uniform(0.7, 1.3, (s, 1))
    period = style.curl_period * rng.uniform(0.8, 1.2, (s, 1))
    phase = 2 * np.pi * arc / period + rng.uniform(0, 2 * np.pi, (s, 1))
    ramp = np.clip(arc / 0.02, 0, 1)
    ramp = ramp * ramp * (3 - 2 * ramp)
    r = (radius * ramp)[..., None]
    offset = r * np.sin(phase)[..., None] * u if style.wave else \
        r * (np.cos(phase)[..., None] * u + np.sin(phase)[..., None] * v - u * np.cos(phase[:, :1])[..., None])
    return pts + offset


def melanin_rgb(eumelanin: np.ndarray, pheomelanin: np.ndarray) -> np.ndarray:
    """Display colour of hair with the given melanin concentrations: ``exp(-sigma_a)`` per channel."""
    sigma = eumelanin[..., None] * EUMELANIN + pheomelanin[..., None] * PHEOMELANIN
    return np.exp(-sigma)


def _colors(n_strands: int, n_points: int, rng: np.random.Generator, multitone: bool) -> np.ndarray:
    eu0 = rng.uniform(0.3, 6.0)  # blonde .. near black
    pheo0 = rng.uniform(0.0, 1.5)
    eu = eu0 * rng.lognormal(0, 0.25, n_strands)
    pheo = pheo0 * rng.lognormal(0, 0.25, n_strands)
    u = np.linspace(0, 1, n_points)[None, :]
    # tips are slightly lighter than roots in all hair (weathering)
    shade = 1 - 0.15 * u
    eu_p = eu[:, None] * shade
    pheo_p = pheo[:, None] * np.ones_like(u)
    if multitone:
        # dyed ends: a lighter, warmer tone from 40-70 % of the length, plus contrasting streaks
        start = rng.uniform(0.4, 0.7, (n_strands, 1))
        fade = np.clip((u - start) / 0.15, 0, 1)
        eu_p = eu_p * (1 - 0.85 * fade)
        pheo_p = pheo_p + 1.2 * fade
        streak = rng.random(n_strands) < 0.12
        eu_p[streak] *= 0.15
        pheo_p[streak] = 0.2
    return melanin_rgb(eu_p, pheo_p).astype(np.float32)


def synthesize(style: str = "straight", n_strands: int = 10_000, n_points: int = 64, seed: int = 0,
               multitone: bool = False) -> Strands:
    """Grow ``n_strands`` strands of ``n_points`` points in a built-in ``style`` (see :data:`STYLES`).

    Units are metres (``meters_per_unit = 1``) and y is up. Deterministic for a given seed.
    """
    if style not in STYLES:
        raise AssetError(f"unknown hairstyle {style!r}; choose one of {', '.join(STYLES)}")
    if n_strands < 1 or n_points < 2:
        raise AssetError(f"need at least 1 strand and 2 points per strand, got {n_strands} x {n_points}")
    st = STYLES[style]
    rng = np.random.default_rng(seed)
    roots, normals = _scalp_roots(n_strands, rng)
    lengths = st.length * rng.uniform(0.85, 1.15, n_strands)
    if st.ponytail:
        lengths += 0.5 * np.linalg.norm(roots - PONYTAIL_TIE, axis=1)
    pts = _grow(roots, normals, lengths, n_points, st, rng)
    pts = push_out_of_head(_curl(pts, st, rng))
    widths = HAIR_WIDTH * (1 - 0.5 * np.linspace(0, 1, n_points))
    strands = Strands.from_array(pts.astype(np.float32), meters_per_unit=1.0, up_axis="Y")
    strands.colors = _colors(n_strands, n_points, rng, multitone).reshape(-1, 3)
    strands.widths = np.tile(widths, n_strands).astype(np.float32)
    return strands
