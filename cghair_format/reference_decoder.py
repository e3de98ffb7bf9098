"""A second decoder of quantized files' geometry, written from the spec (sections 4.1-4.5, 5, 6.1 and
"Arithmetic") alone: slow, readable, one point at a time in Python floats.

It shares no floating-point code with the compiled decoder (:mod:`._decoder`, :mod:`.geometry`,
:mod:`.quantize`): the predictor plans and weights, the cards and their angles' cosines, the strips,
the card map and its Jacobian, the Newton searches, the most alike strand and the children are its
own. Python's float operations are the spec's (binary64, each rounded once, no fused multiply-add),
so where both follow the spec they decode the same bits; :func:`decode_points` proves it file by
file (``cgh validate --reference``, tests/format/test_reference_decoder.py). What is integer and
shared: the container and META (:mod:`.codec`), the array records (:mod:`.streams`) and the entropy
coded residuals (4.3.2, :func:`.residual_coder.read_residuals`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import zstandard

from . import codec, container
from .errors import InvalidContentError
from .residual_coder import read_residuals
from .streams import StreamReader

TWO_PI = 6.283185307179586  # spec 4.2: the float64 nearest 2 pi
CLOSE = 1e-4  # spec 4.3: a search stops within a hundredth of a step (squared)
CANDIDATES = 32  # spec 4.3.1: the most alike strand among at most this many before a strand
WEIGHT_ONE = 1024  # spec 4.5: children's weights in units of 1/1024
CHILD_STEPS, CHILD_HALVINGS = 8, 4  # spec 4.5: a child's searches, whatever META says


# --- arithmetic (spec 4, "Arithmetic") -------------------------------------------------------------

def add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def scale(s, a):
    return [s * a[0], s * a[1], s * a[2]]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    return math.sqrt(dot(a, a))


def normalize(a):
    d = at_least(norm(a), 1e-30)
    return [a[0] / d, a[1] / d, a[2] / d]


def at_least(x: float, c: float) -> float:
    """``max(x, c)`` as the spec has it: ``x`` unless ``x < c`` (a NaN stays)."""
    return c if x < c else x


def largest(values) -> float:
    """The largest of ``values``; NaN if any is."""
    out = -math.inf
    for v in values:
        if v > out or v != v:
            out = v
        if out != out:
            break
    return out


def f32(x: float) -> float:
    return float(np.float32(x))


def wrap64(x: int) -> int:
    """``x`` as int64 arithmetic that wraps leaves it."""
    return (x + (1 << 63)) % (1 << 64) - (1 << 63)


# --- 4.1 the hierarchical predictor ----------------------------------------------------------------

def plan(n: int, stride: int, taps: list[int] | None):
    """Base indices and, per level, ``[(i, nb(i), w(i))]`` (Lagrange weights, float64)."""
    base = sorted(set(range(0, n, stride)) | {n - 1})
    known = set(base)
    levels = []
    h = stride // 2
    while h >= 1:
        idx = [i for i in range(h, n - 1, 2 * h) if i not in known]
        if idx:
            half = (4 if taps is None else taps[len(levels)]) // 2
            rows = []
            for i in idx:
                nb = sorted(j for j in known if j < i)[-half:] + sorted(j for j in known if j > i)[:half]
                weights = []
                for j in nb:
                    w = 1.0
                    for m in nb:
                        if m != j:
                            w = w * ((i - m) / (j - m))
                    weights.append(w)
                rows.append((i, nb, weights))
            levels.append(rows)
            known |= set(idx)
        h //= 2
    return base, levels


def interpolate(x, nb, w):
    """``sum over j in nb of w_j x[j]``, left to right (x: floats or 3-vectors)."""
    if isinstance(x[nb[0]], list):
        acc = scale(w[0], x[nb[0]])
        for j, wj in zip(nb[1:], w[1:], strict=True):
            acc = add(acc, scale(wj, x[j]))
        return acc
    acc = w[0] * x[nb[0]]
    for j, wj in zip(nb[1:], w[1:], strict=True):
        acc = acc + wj * x[j]
    return acc


def hier_rows(r: StreamReader, rows: int, n: int, stride: int, name: str) -> list[list[float]]:
    """``H(x, rows, n)`` (4.1): its records read from ``r``, each row decoded."""
    base, levels = plan(n, stride, None)
    res_base = r.ints((rows, len(base)), f"{name} base")
    res_levels = [r.ints((rows, len(lv)), f"{name} level {k}") for k, lv in enumerate(levels)]
    out = []
    for row in range(rows):
        x = [0.0] * n
        for t, i in enumerate(base):
            if t == 0:
                pred = 0.0
            elif t == 1:
                pred = x[base[0]]
            else:
                a, b = base[t - 2], base[t - 1]
                pred = x[b] + (x[b] - x[a]) * ((i - b) / (b - a))
            x[i] = pred + float(res_base[row, t])
        for lv, rows_l in enumerate(levels):
            for col, (i, nb, w) in enumerate(rows_l):
                x[i] = interpolate(x, nb, w) + float(res_levels[lv][row, col])
        out.append(x)
    return out


# --- 4.2 cards and 5 strips -----------------------------------------------------------------------

def turn_cos_sin(alpha: float) -> tuple[float, float]:
    """Cosine and sine of ``alpha`` turns (4.2)."""
    v = 4 * alpha + 0.5
    k = float(math.floor(v)) if math.isfinite(v) else math.nan
    x = (alpha - k / 4) * TWO_PI
    t = x * x
    c = 1.0
    for n in range(16, 0, -2):
        c = 1 - (t / (n * (n - 1))) * c
    s = 1.0
    for n in range(17, 1, -2):
        s = 1 - (t / (n * (n - 1))) * s
    s = x * s
    quarter = k - 4 * math.floor(k / 4) if math.isfinite(k) else math.nan
    return {0: (c, s), 1: (-s, c), 2: (-c, -s), 3: (s, -c)}.get(quarter, (math.nan, math.nan))


def tangents(p):
    """Section 5's ``t_k`` of points ``p [M+1]``."""
    m = len(p) - 1
    return [normalize(sub(p[1], p[0]) if k == 0 else sub(p[m], p[m - 1]) if k == m else sub(p[k + 1], p[k - 1]))
            for k in range(m + 1)]


def across(t):
    e = [0.0, 0.0, 0.0]
    a = [abs(t[0]), abs(t[1]), abs(t[2])]
    e[a.index(min(a))] = 1.0  # the first on ties
    return normalize(cross(e, t))


@dataclass
class Card:
    spine: list  # [M+1] float32 values (as floats)
    normal: list
    half_width: list


def decode_cards(payload: bytes, c: int, m1: int, q: dict) -> list[Card]:
    r = StreamReader(payload, "CARD")
    qc, stride = q["card_step"], q["base_stride"]
    spine_rows = hier_rows(r, 3 * c, m1, stride, "spine")
    angle_rows = hier_rows(r, c, m1, stride, "normal angle")
    width_rows = hier_rows(r, c, m1, stride, "half_width")
    cards = []
    for ci in range(c):
        spine = [[spine_rows[3 * ci + a][k] * qc for a in range(3)] for k in range(m1)]
        t = tangents(spine)
        normals, ref = [], None
        for k in range(m1):
            if k == 0:
                ref = across(t[0])
            else:
                v = sub(ref, scale(dot(ref, t[k]), t[k]))
                ref = across(t[k]) if norm(v) < 1e-6 else normalize(v)
            cos, sin = turn_cos_sin(angle_rows[ci][k] / 2.0 ** q["normal_bits"])
            normals.append(normalize(add(scale(cos, ref), scale(sin, cross(t[k], ref)))))
        widths = [x * qc for x in width_rows[ci]]
        cards.append(Card([[f32(x) for x in p] for p in spine], [[f32(x) for x in n] for n in normals],
                          [f32(at_least(w, 0.0)) for w in widths]))
    return cards


@dataclass
class Strip:
    left: list  # L_k
    right: list  # R_k
    normal: list  # n_k
    su: float
    sv: float


def strip(card: Card, q: float) -> Strip:
    t = tangents(card.spine)
    left, right = [], []
    for p, n, w, tk in zip(card.spine, card.normal, card.half_width, t, strict=True):
        b = normalize(cross(n, tk))
        left.append(sub(p, scale(w, b)))
        right.append(add(p, scale(w, b)))
    m = len(left) - 1
    longest = largest([norm(sub(rail[k + 1], rail[k])) for k in range(m) for rail in (left, right)])
    return Strip(left, right, card.normal, at_least(m * longest, q), at_least(2 * largest(card.half_width), q))


# --- 6.1 the card map, 4.3 its Jacobian -------------------------------------------------------------

def card_map(st: Strip, z, jacobian: bool = False):
    """The world point of ``z = (u, v, delta)`` on the strip and, with ``jacobian``, ``(Ju, Jv, Jd)``."""
    m = len(st.left) - 1
    u, v, delta = z
    s = u * m
    k = float(math.floor(s)) if math.isfinite(s) else s
    if not (k >= 0):  # also NaN
        k = 0.0
    if k > m - 1:
        k = float(m - 1)
    f = s - k
    up = f + v > 1
    e = v - (1.0 if up else 0.0)
    k = int(k)
    n0, n1 = st.normal[k], st.normal[k + 1]
    if up:  # triangle 2k+1: (R_k, R_k+1, L_k+1)
        a, ef, ev = st.right[k], sub(st.right[k + 1], st.right[k]), sub(st.right[k + 1], st.left[k + 1])
        na, nf, nv = n0, sub(n1, n0), sub(n1, n1)
    else:  # triangle 2k: (L_k, R_k, L_k+1)
        a, ef, ev = st.left[k], sub(st.left[k + 1], st.left[k]), sub(st.right[k], st.left[k])
        na, nf, nv = n0, sub(n1, n0), sub(n0, n0)
    n = add(add(na, scale(f, nf)), scale(e, nv))
    length = at_least(norm(n), 1e-30)
    nh = [n[0] / length, n[1] / length, n[2] / length]
    x = add(add(add(a, scale(f, ef)), scale(e, ev)), scale(delta, nh))
    if not jacobian:
        return x
    pf, pv = dot(nh, nf), dot(nh, nv)
    ju = [m * (ef[i] + delta * ((nf[i] - nh[i] * pf) / length)) for i in range(3)]
    jv = [ev[i] + delta * ((nv[i] - nh[i] * pv) / length) for i in range(3)]
    return x, (ju, jv, nh)


def solve(j, r):
    """``J d = r`` by Cramer's rule (4.3); 0 unless ``|det| > 1e-30``."""
    ju, jv, jd = j
    bc, ca, ab = cross(jv, jd), cross(jd, ju), cross(ju, jv)
    det = dot(ju, bc)
    if not (abs(det) > 1e-30):
        return [0.0, 0.0, 0.0]
    return [dot(r, bc) / det, dot(r, ca) / det, dot(r, ab) / det]


def search(st: Strip, z, goal, steps: int, halvings: int, gd: float):
    x, j = card_map(st, z, True)
    miss = sub(goal, x)
    m2 = dot(miss, miss)
    for _ in range(steps):
        if m2 * (gd * gd) <= CLOSE:
            break
        d = solve(j, miss)
        if not all(math.isfinite(e) for e in d):
            break
        t = 1.0
        for _ in range(halvings + 1):
            cand = add(z, scale(t, d))
            x2, j2 = card_map(st, cand, True)
            miss2 = sub(goal, x2)
            d2 = dot(miss2, miss2)
            if d2 < m2:
                z, j, miss, m2 = cand, j2, miss2, d2
                break
            t = t / 2
        else:
            break
    return z, j


def stretch(x: float, most: float) -> float:
    if x > most:
        return most
    if not (x >= 1):
        return 1.0
    return x


def place(st: Strip, p0, goal, g, q: dict):
    z, j = search(st, [p0[0] / g[0], p0[1] / g[1], p0[2] / g[2]], goal, q["newton_steps"], q["newton_halvings"],
                  g[2])
    pred = [z[0] * g[0], z[1] * g[1], z[2] * g[2]]
    if not all(math.isfinite(e) for e in pred):
        pred = list(p0)
        _, j = card_map(st, [p0[0] / g[0], p0[1] / g[1], p0[2] / g[2]], True)
    f = [stretch(g[ch] / (norm(j[ch]) * g[2]), float(q["stretch_max"])) for ch in range(2)] + [1.0]
    return pred, f


# --- 4.3 strand points --------------------------------------------------------------------------

def unlikeness(w, wm, base, ks, h) -> float:
    total = 0.0
    for k in ks:
        d = sub(sub(w[base[k + 1]], w[base[k]]), sub(wm[base[k + 1]], wm[base[k]]))
        total = total + dot(d, d)
    d = sub(w[base[h]], wm[base[h]])
    return total + dot(d, d) / 32


def most_alike(w, earlier, base, ks, h) -> int:
    """Of ``earlier`` (strands before this one on its card, nearest first, their ``(y, W, r)``), the
    index of the first with the smallest unlikeness (a NaN never is smaller)."""
    best, pick = None, 0
    for k, (_, wm, _) in enumerate(earlier[:CANDIDATES]):
        u = unlikeness(w, wm, base, ks, h)
        if best is None or u < best:
            best, pick = u, k
    return pick


def decode_strand(st: Strip, r, earlier, base, levels, q: dict):
    """One strand's ``y`` and ``W`` (4.3) from its residuals ``r [N][3]`` (neighbour prediction undone;
    its level residuals restored here where they are differences from the most alike strand's)."""
    g = [st.su / q["step"], st.sv / q["step"], 1 / q["step"]]
    y, w = [None] * (base[-1] + 1), [None] * (base[-1] + 1)
    guide = q["base_guide"] if earlier else 0

    def world(i):
        w[i] = card_map(st, [y[i][0] / g[0], y[i][1] / g[1], y[i][2] / g[2]])

    for t, i in enumerate(base):
        if guide and t == 0:
            y[i] = [earlier[0][0][i][ch] + float(r[t][ch]) * 1.0 for ch in range(3)]
        elif guide:
            b = base[t - 1]
            yn, wn, _ = earlier[0]
            rho = 1.0
            if t >= 2 and guide == 2:
                a = base[t - 2]
                d, e = sub(w[b], w[a]), sub(wn[b], wn[a])
                if dot(e, e) > 0:
                    rho = math.sqrt(dot(d, d) / dot(e, e))
                rho = 0.5 if not (rho >= 0.5) else min(rho, 2.0)
            if t >= 2 and guide == 3:
                ks = [k for k in (t - 3, t - 2) if k >= 0]
                yn, wn, _ = earlier[most_alike(w, earlier, base, ks, t - 1)]
            p0 = add(y[b], scale(rho, sub(yn[i], yn[b])))
            goal = add(w[b], scale(rho, sub(wn[i], wn[b])))
            pred, f = place(st, p0, goal, g, q)
            y[i] = [pred[ch] + float(r[t][ch]) * f[ch] for ch in range(3)]
        else:
            pred = [0.0, 0.0, 0.0]
            for ch in range(3):
                if t >= 1 and (t == 1 or q["base_order"][ch] == 1):
                    pred[ch] = y[base[t - 1]][ch]
                elif t >= 2:
                    a, b = base[t - 2], base[t - 1]
                    pred[ch] = y[b][ch] + (y[b][ch] - y[a][ch]) * ((i - b) / (b - a))
            y[i] = [pred[ch] + float(r[t][ch]) for ch in range(3)]
        world(i)
    refs = [None] * (len(base) - 1)
    if q["level_guide"] and earlier:
        for k in range(len(base) - 1):
            ks = [j for j in (k - 1, k, k + 1) if 0 <= j <= len(base) - 2]
            refs[k] = earlier[most_alike(w, earlier, base, ks, k + 1)][2]
    col = len(base)
    for rows in levels:
        for i, nb, wt in rows:
            pred, f = place(st, interpolate(y, nb, wt), interpolate(w, nb, wt), g, q)
            k = max(kk for kk in range(len(base) - 1) if base[kk] < i)
            if refs[k] is not None:
                r[col] = [wrap64(r[col][ch] + refs[k][col][ch]) for ch in range(3)]
            y[i] = [pred[ch] + float(r[col][ch]) * f[ch] for ch in range(3)]
            world(i)
            col += 1
    return y, w, g


# --- 4.5 children -------------------------------------------------------------------------------

def child_points(guides, parents, weights, resampled: bool):
    w0, w1, w2 = (x / WEIGHT_ONE for x in weights)
    p = len(guides[parents[0]])
    blend = [add(add(scale(w0, guides[parents[0]][i]), scale(w1, guides[parents[1]][i])),
                 scale(w2, guides[parents[2]][i])) for i in range(p)]
    if not resampled:
        return blend
    length = [0.0]
    for i in range(1, p):
        length.append(length[i - 1] + norm(sub(blend[i], blend[i - 1])))
    out, j = [], 0
    for i in range(p - 1):
        t = length[p - 1] * i / (p - 1)
        while j < p - 2 and length[j + 1] < t:
            j += 1
        f = (t - length[j]) / (length[j + 1] - length[j]) if length[j + 1] > length[j] else 0.0
        out.append(add(blend[j], scale(f, sub(blend[j + 1], blend[j]))))
    out.append(blend[p - 1])
    return out


def place_child(st: Strip, goal, step: float):
    z, prev, out = [0.0, 0.5, 0.0], None, []
    for i, x in enumerate(goal):
        z, _ = search(st, z, x, CHILD_STEPS, CHILD_HALVINGS, 1 / step)
        out.append(z)
        nxt = list(z) if i == 0 else [2 * z[ch] - prev[ch] for ch in range(3)]
        prev, z = z, nxt
    return out


# --- the file -----------------------------------------------------------------------------------

@dataclass
class Decoded:
    """What :func:`decode_points` decodes: the strands ``index [n]`` (their indices in the file), their
    card coordinates in float64 (``coordinates [n, P, 3]``: a guide's ``y / g``, a child's search results),
    and as a reader gets them, rounded to float32: ``uvd [n, P, 3]`` and world ``points [n, P, 3]``, and
    each strand's own point count ``counts [n]`` (PCNT's, else ``P``: the points past it are placeholders,
    decoded alike and then dropped)."""

    index: np.ndarray
    coordinates: np.ndarray
    uvd: np.ndarray
    points: np.ndarray
    counts: np.ndarray


def decode_points(data: bytes, cards: set[int] | None = None) -> Decoded:
    """The strands of a quantized .cgh file (its bytes) on ``cards`` (all if None), as spec 4.3, 4.5 and
    6.1 define them. A child is decoded where its card and its parents' cards are among ``cards``."""
    _, table = container.verify(data, set(codec.KNOWN_CHUNKS))
    infos = {i.type: i for i in table}
    meta = codec.schema.parse(container.payload(data, infos["META"]))
    q = meta["quant"]
    if q["lossless"]:
        raise InvalidContentError("a lossless file stores its card coordinates: there is nothing to predict",
                                  chunk="META")
    s, p, m = meta["strands"], meta["points"], meta["segments"]
    card_list = decode_cards(container.payload(data, infos["CARD"]), meta["cards"], m + 1, q)
    strd = StreamReader(container.payload(data, infos["STRD"]), "STRD")
    strand_card = [int(c) for c in np.cumsum(strd.ints((s,), "strand_card"))]
    g_count = s - q.get("children", 0)
    base, levels = plan(p, q["base_stride"], q["level_taps"])
    widths = [len(base)] + [len(rows) for rows in levels]
    stored = read_residuals(strd, np.asarray(strand_card[:g_count], np.int64), widths, q["neighbour_classes"])
    starts = np.cumsum([0] + widths)
    wanted = set(range(meta["cards"])) if cards is None else set(cards)
    strips = {c: strip(card_list[c], q["step"]) for c in wanted}

    residuals, last = {}, {}  # neighbour prediction undone (4.3.1), strand by strand in file order
    for st_i in range(g_count):
        c = strand_card[st_i]
        r = [[int(x) for x in row] for row in stored[st_i]]
        nb = last.get(c)
        if nb is not None:
            for a, mask in enumerate(q["neighbour"]):
                for col in range(starts[a], starts[a + 1]):
                    for ch in range(3):
                        if mask >> ch & 1:
                            r[col][ch] = wrap64(r[col][ch] + residuals[nb][col][ch])
        residuals[st_i] = r
        last[c] = st_i

    coords, world, before = {}, {}, {}
    for st_i in range(g_count):
        c = strand_card[st_i]
        if c not in wanted:
            continue
        earlier = before.setdefault(c, [])
        y, w, g = decode_strand(strips[c], residuals[st_i], earlier, base, levels, q)
        earlier.insert(0, (y, w, residuals[st_i]))
        coords[st_i] = [[y[i][ch] / g[ch] for ch in range(3)] for i in range(p)]
    if g_count < s:
        fam = codec.reader.read_family(container.payload(data, infos[codec.FAMILY_CHUNK]), g_count, s - g_count)
        for k in range(s - g_count):
            c, parents = strand_card[g_count + k], [int(x) for x in fam.parents[k]]
            if c not in wanted or any(x not in coords for x in parents):
                continue
            for x in parents:
                if x not in world:
                    world[x] = [card_map(strips[strand_card[x]], [f32(e) for e in pt]) for pt in coords[x]]
            goal = child_points(world, parents, [int(x) for x in fam.weights[k]], bool(fam.respaced[k]))
            coords[g_count + k] = place_child(strips[c], goal, q["step"])
    counts = [p] * s
    if "PCNT" in infos:  # spec 3: ints[S], each in 2..P
        pcnt = StreamReader(container.payload(data, infos["PCNT"]), "PCNT")
        counts = [int(n) for n in pcnt.ints((s,), "point counts")]
        pcnt.finish()
        if min(counts) < 2 or max(counts) > p or min(counts) == p:
            raise InvalidContentError(f"point counts must lie in [2, {p}], some below {p}", chunk="PCNT")
    index = np.array(sorted(coords), np.int64)
    coordinates = np.array([coords[i] for i in index], np.float64).reshape(len(index), p, 3)
    uvd = coordinates.astype(np.float32)
    points = np.array([[[f32(e) for e in card_map(strips[strand_card[i]], [float(x) for x in pt])] for pt in row]
                       for i, row in zip(index, uvd, strict=True)], np.float32).reshape(len(index), p, 3)
    return Decoded(index, coordinates, uvd, points, np.array([counts[i] for i in index], np.int64))


# --- 4.6 animation ----------------------------------------------------------------------------------

def rest_cards(data: bytes, meta: dict) -> list[Card]:
    """The rest cards as a decoder has them: 4.2's, or a lossless file's float32 values as stored."""
    infos = {i.type: i for i in container.read_table(data)[1]}
    c, m1 = meta["cards"], meta["segments"] + 1
    if not meta["quant"]["lossless"]:
        return decode_cards(container.payload(data, infos["CARD"]), c, m1, meta["quant"])
    r = StreamReader(container.payload(data, infos["CARD"]), "CARD")
    spine, normal = r.array((c, m1, 3), "spine", ("<f4",)), r.array((c, m1, 3), "normal", ("<f4",))
    half_width = r.array((c, m1), "half_width", ("<f4",))
    return [Card(spine[ci].tolist(), normal[ci].tolist(), half_width[ci].tolist()) for ci in range(c)]


def decode_frame(data: bytes, t: int) -> list[Card]:
    """Frame ``t``'s cards (4.6), from its block alone; half-widths are the rest cards'."""
    _, table = container.verify(data, set(codec.KNOWN_CHUNKS))
    infos = {i.type: i for i in table}
    meta = codec.schema.parse(container.payload(data, infos["META"]))
    anim, rest = meta["animation"], rest_cards(data, meta)
    g = anim["keyframe_interval"]
    n = min(g, anim["frames"] - t // g * g)
    r = StreamReader(block(container.payload(data, infos["ANIM"]), anim, t // g), "ANIM")
    c, m1, j = meta["cards"], meta["segments"] + 1, t % g
    if meta["quant"]["lossless"]:
        spine = r.array((n, c, m1, 3), "spine", ("<f4",))[j]
        normal = r.array((n, c, m1, 3), "normal", ("<f4",))[j]
        return [Card(spine[ci].tolist(), normal[ci].tolist(), rest[ci].half_width) for ci in range(c)]
    rs = r.ints((n, c, m1, 3), "spine residuals").tolist()
    ra = r.ints((n, c, m1), "angle residuals").tolist()
    qa, bits = anim["step"], anim["normal_bits"]
    turn = 1 << bits
    out = []
    for ci in range(c):
        spine = [[0.0] * 3 for _ in range(m1)]
        for a in range(3):
            e = [along_card([x[ci][k][a] for k in range(m1)]) for x in rs]  # e[i][k]: frame i's residual
            for k in range(m1):  # (round: half to even, as the spec's)
                spine[k][a] = float(integer_at(round(rest[ci].spine[k][a] / qa), [x[k] for x in e], j)) * qa
        angles = [0] * m1
        for i in range(j + 1):
            turned = along_card([x % turn for x in ra[i][ci]])
            angles = [(angles[k] + turned[k]) % turn for k in range(m1)]
        out.append(frame_card(spine, angles, bits, rest[ci].half_width))
    return out


def along_card(d: list[int]) -> list[int]:
    """The running sums of ``d`` along a card (4.6), int64 that wraps."""
    out, total = [], 0
    for x in d:
        total = wrap64(total + x)
        out.append(total)
    return out


def block(payload: bytes, anim: dict, b: int) -> bytes:
    """Block ``b``'s bytes (4.6), decompressed."""
    count = (anim["frames"] + anim["keyframe_interval"] - 1) // anim["keyframe_interval"]
    start = 4 + 12 * count
    for k in range(b):
        start += int.from_bytes(payload[4 + 12 * k:8 + 12 * k], "little")
    stored = int.from_bytes(payload[4 + 12 * b:8 + 12 * b], "little")
    raw = int.from_bytes(payload[8 + 12 * b:12 + 12 * b], "little")
    body = payload[start:start + stored]
    return zstandard.ZstdDecompressor().decompress(body, max_output_size=raw) if payload[12 + 12 * b] == 1 else body


def integer_at(base: int, residuals: list[int], j: int) -> int:
    """``Q_j`` of one spine coordinate (4.6): int64 arithmetic that wraps."""
    q = [wrap64(base + residuals[0])]
    for i in range(1, j + 1):
        pred = q[0] if i == 1 else wrap64(2 * q[i - 1] - q[i - 2])
        q.append(wrap64(pred + residuals[i]))
    return q[j]


def frame_card(spine: list, angles: list, bits: int, half_width: list) -> Card:
    """A card of a frame from its float64 spine and normal angles (4.6, as 4.2)."""
    t = tangents(spine)
    normals, ref = [], None
    for k in range(len(spine)):
        ref = across(t[0]) if k == 0 else _carried(ref, t[k])
        cos, sin = turn_cos_sin(angles[k] / 2.0 ** bits)
        normals.append(normalize(add(scale(cos, ref), scale(sin, cross(t[k], ref)))))
    return Card([[f32(x) for x in p] for p in spine], [[f32(x) for x in n] for n in normals], half_width)


def _carried(ref, t):
    """4.2's ``r_k`` from ``r_{k-1}`` and ``t_k``."""
    v = sub(ref, scale(dot(ref, t), t))
    return across(t) if norm(v) < 1e-6 else normalize(v)


def frame_points(data: bytes, t: int) -> np.ndarray:
    """Every strand point ``[S, P, 3]`` (float32) of frame ``t``: 6.1 on its cards with the file's card
    coordinates (the compiled decoder's: they are the rest pose's, which :func:`decode_points` checks)."""
    from .codec import decode

    asset = decode(data)
    strips = [strip(card, 0.0) for card in decode_frame(data, t)]
    return np.array([[[f32(e) for e in card_map(strips[c], [float(x) for x in pt])] for pt in row]
                     for c, row in zip(asset.strand_card, asset.uvd, strict=True)], np.float32)


def evenly_spaced_cards(count: int, wanted: int | None) -> set[int] | None:
    """``wanted`` of ``count`` cards, evenly spaced (all: None)."""
    if wanted is None or wanted >= count:
        return None
    return {int(c) for c in np.linspace(0, count - 1, wanted).round()}


def compare(data: bytes, cards: set[int] | None = None) -> tuple[int, int]:
    """Decode a quantized file with the compiled decoder and with :func:`decode_points`; return how many
    strands were compared and on how many the point counts, card coordinates or points (placeholders
    included) differ in any bit."""
    from .codec import decode
    from .geometry import strand_points

    asset = decode(data)
    ref = decode_points(data, cards)
    uvd = asset.uvd[ref.index]
    points = strand_points(asset.cards, asset.strand_card, asset.uvd)[ref.index]
    differ = ((uvd.view(np.uint32) != ref.uvd.view(np.uint32))
              | (points.view(np.uint32) != ref.points.view(np.uint32))).any(axis=(1, 2))
    differ |= asset.counts[ref.index] != ref.counts
    return len(ref.index), int(differ.sum())


def compare_frames(data: bytes) -> tuple[int, int]:
    """Decode every frame of a quantized file's animation with the compiled reader and with
    :func:`decode_frame`; return how many frames were compared and on how many a card's spine or normal
    differs in any bit."""
    from .codec import read_animation

    fast = read_animation(data)
    differ = 0
    for f in range(fast.frames):
        cards = decode_frame(data, f)
        spine = np.array([c.spine for c in cards], np.float32)
        normal = np.array([c.normal for c in cards], np.float32)
        differ += spine.tobytes() != fast.spine[f].tobytes() or normal.tobytes() != fast.normal[f].tobytes()
    return fast.frames, differ
