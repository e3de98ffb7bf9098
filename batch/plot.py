"""The report's plot, drawn with Pillow: file size against strand count (log-log) per profile, with the
baseline coder's size, and the geometry's ratio to the baseline against strand count."""

from __future__ import annotations

import math
from pathlib import Path

from cghair_format.atomic import atomic_path

from .report import profiles_of

PALETTE = ((0, 114, 178), (213, 94, 0), (0, 158, 115), (204, 121, 167))  # Okabe-Ito, one per profile
BASELINE = (150, 150, 150)
PANEL = (560, 440)
MARGIN = (80, 40, 20, 60)  # left, top, right, bottom of each panel
DOT = 3
UNITS = ("B", "kB", "MB", "GB", "TB")


def draw_report(rows: list[dict], path: str | Path) -> Path:
    """Write a PNG of the rows that succeeded: bytes against strands, and ratio to the baseline."""
    from PIL import Image, ImageDraw, ImageFont

    ok = [r for r in rows if r["status"] == "ok" and r.get("strands")]
    profiles = profiles_of(ok)
    img = Image.new("RGB", (2 * PANEL[0], PANEL[1]), "white")
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default(size=13)
    sizes = [(p, PALETTE[i % len(PALETTE)], [(r["strands"], r[f"bytes_{p}"]) for r in ok if f"bytes_{p}" in r])
             for i, p in enumerate(profiles)]
    coded = [p for p in profiles if any(f"baseline_bytes_{p}" in r for r in ok)]  # lossless has no baseline
    if coded:
        key = f"baseline_bytes_{coded[0]}"
        sizes.append((f"baseline at {coded[0]}'s bound", BASELINE, [(r["strands"], r[key]) for r in ok if key in r]))
    _panel(draw, font, (0, 0), "file bytes (log) against strands (log)", sizes, log_y=True)
    ratios = [(p, PALETTE[i % len(PALETTE)], [(r["strands"], r[f"ratio_{p}"]) for r in ok if f"ratio_{p}" in r])
              for i, p in enumerate(profiles)]
    _panel(draw, font, (PANEL[0], 0), "geometry / baseline against strands (log)", ratios, log_y=False, rule=1.0)
    path = Path(path)
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")
    return path


def _panel(draw, font, origin, title, series, log_y: bool, rule: float | None = None) -> None:
    """One scatter panel at ``origin``: ``series`` of (label, colour, [(strands, value)]); x is log."""
    points = [(x, y) for _, _, pts in series for x, y in pts if x > 0 and (y > 0 or not log_y)]
    ox, oy = origin
    left, top, right, bottom = ox + MARGIN[0], oy + MARGIN[1], ox + PANEL[0] - MARGIN[2], oy + PANEL[1] - MARGIN[3]
    draw.text((left, oy + 12), title, fill="black", font=font)
    draw.rectangle([left, top, right, bottom], outline=(120, 120, 120))
    if not points:
        draw.text((left + 10, top + 10), "no files", fill="black", font=font)
        return
    fy = math.log10 if log_y else float
    x0, x1 = _range([math.log10(x) for x, _ in points], whole=True)
    y0, y1 = _range([fy(y) for _, y in points] + ([rule] if rule is not None else []), whole=log_y)

    def px(x: float, y: float) -> tuple[float, float]:
        return (left + (math.log10(x) - x0) / (x1 - x0) * (right - left),
                bottom - (fy(y) - y0) / (y1 - y0) * (bottom - top))

    for e in range(int(x0), int(x1) + 1):
        gx = px(10.0 ** e, 10.0 ** y0 if log_y else y0)[0]
        draw.line([(gx, top), (gx, bottom)], fill=(230, 230, 230))
        draw.text((gx, bottom + 6), f"{10 ** e:g}", fill="black", font=font, anchor="mt")
    for tick in _ticks(y0, y1, log_y):
        gy = px(10.0 ** x0, tick)[1]
        draw.line([(left, gy), (right, gy)], fill=(230, 230, 230))
        draw.text((left - 6, gy), _bytes(tick) if log_y else f"{tick:.3g}", fill="black", font=font, anchor="rm")
    if rule is not None:
        gy = px(10.0 ** x0, rule)[1]
        draw.line([(left, gy), (right, gy)], fill=(0, 0, 0))
    for i, (label, colour, pts) in enumerate(series):
        for x, y in pts:
            if x > 0 and (y > 0 or not log_y):
                cx, cy = px(x, y)
                draw.ellipse([cx - DOT, cy - DOT, cx + DOT, cy + DOT], fill=colour)
        ly = top + 14 + 16 * i
        draw.ellipse([left + 12 - DOT, ly - DOT, left + 12 + DOT, ly + DOT], fill=colour)
        draw.text((left + 20, ly), label, fill=colour, font=font, anchor="lm")


def _bytes(n: float) -> str:
    """A power of ten of bytes as "100 kB"."""
    e = round(math.log10(n))
    unit = min(max(e // 3, 0), len(UNITS) - 1)
    return f"{10 ** (e - 3 * unit):g} {UNITS[unit]}"


def _range(values: list[float], whole: bool) -> tuple[float, float]:
    lo, hi = min(values), max(values)
    if whole:
        return math.floor(lo - 0.05), max(math.ceil(hi + 0.05), math.floor(lo - 0.05) + 1)
    pad = max(0.05 * (hi - lo), 0.05)
    return lo - pad, hi + pad


def _ticks(y0: float, y1: float, log_y: bool) -> list[float]:
    if log_y:
        return [10.0 ** e for e in range(int(y0), int(y1) + 1)]
    step = 10 ** math.floor(math.log10((y1 - y0) / 2))
    step *= 5 if (y1 - y0) / step > 20 else 2 if (y1 - y0) / step > 8 else 1
    return [step * k for k in range(math.ceil(y0 / step), math.floor(y1 / step) + 1)]
