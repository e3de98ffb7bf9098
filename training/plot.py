"""The ablation plot: held-out PSNR against appearance size (log scale), our variants next to the
paper's, drawn with Pillow (already a training dependency): one scatter plot needs no plotting library."""

from __future__ import annotations

import math
from pathlib import Path

COLOURS = {"unique": (31, 119, 180), "no-card-clustering": (148, 103, 189), "single-sh": (44, 160, 44),
           "multi-sh": (255, 127, 14), "latents": (214, 39, 40)}
SIZE = (900, 600)
MARGIN = (90, 30, 200, 70)  # left, top, right (legend), bottom
MARK = 7  # marker radius in pixels
UNITS = ("B", "kB", "MB", "GB", "TB")


def _label(exponent: int) -> str:
    """``10 ** exponent`` bytes as "100 kB"."""
    unit = min(max(exponent // 3, 0), len(UNITS) - 1)
    return f"{10 ** (exponent - 3 * unit):g} {UNITS[unit]}"


def _nice_step(span: float) -> float:
    for step in (0.5, 1, 2, 5, 10, 20):
        if span / step <= 10:
            return step
    return 50.0


def plot_ablation(rows: list[dict], paper: dict[str, tuple[float, float]], path: str | Path, title: str = "") -> Path:
    """Write a PNG of PSNR against appearance bytes for ``rows`` (ablation rows with ``variant``,
    ``psnr`` and ``appearance_bytes``) as dots, and ``paper`` (variant -> (PSNR, MB)) as hollow squares."""
    from PIL import Image, ImageDraw, ImageFont

    ours = [(r["variant"], math.log10(r["appearance_bytes"]), r["psnr"]) for r in rows]
    paper = [(v, math.log10(mb * 1e6), psnr) for v, (psnr, mb) in paper.items()]
    xs = [p[1] for p in ours + paper]
    ys = [p[2] for p in ours + paper]
    x0, x1 = math.floor(min(xs) - 0.1), math.ceil(max(xs) + 0.1)  # whole decades, no point on an edge
    x1 = max(x1, x0 + 1)
    step = _nice_step(max(ys) - min(ys) + 1)
    y0, y1 = step * math.floor((min(ys) - 0.5) / step), step * math.ceil((max(ys) + 0.5) / step)

    img = Image.new("RGB", SIZE, "white")
    draw = ImageDraw.Draw(img)
    font, small = ImageFont.load_default(size=15), ImageFont.load_default(size=12)
    left, top, right, bottom = MARGIN[0], MARGIN[1], SIZE[0] - MARGIN[2], SIZE[1] - MARGIN[3]

    def px(x: float, y: float) -> tuple[float, float]:
        return left + (x - x0) / (x1 - x0) * (right - left), bottom - (y - y0) / (y1 - y0) * (bottom - top)

    for e in range(x0, x1 + 1):  # decades, with a label each
        gx = px(e, y0)[0]
        draw.line([(gx, top), (gx, bottom)], fill=(225, 225, 225))
        draw.text((gx, bottom + 8), _label(e), fill="black", font=small, anchor="mt")
    y = y0
    while y <= y1 + 1e-9:
        gy = px(x0, y)[1]
        draw.line([(left, gy), (right, gy)], fill=(225, 225, 225))
        draw.text((left - 8, gy), f"{y:g}", fill="black", font=small, anchor="rm")
        y += step
    draw.rectangle([left, top, right, bottom], outline="black")
    draw.text(((left + right) / 2, SIZE[1] - 20), "appearance size (bytes, log scale)", fill="black", font=font,
              anchor="mm")
    ylabel = Image.new("RGB", (bottom - top, 24), "white")
    ImageDraw.Draw(ylabel).text(((bottom - top) / 2, 12), "held-out PSNR (dB)", fill="black", font=font, anchor="mm")
    img.paste(ylabel.rotate(90, expand=True), (12, top))
    if title:
        draw.text(((left + right) / 2, top / 2), title, fill="black", font=font, anchor="mm")

    for variant, x, y in paper:
        cx, cy = px(x, y)
        draw.rectangle([cx - MARK, cy - MARK, cx + MARK, cy + MARK], outline=COLOURS[variant], width=2)
    for variant, x, y in ours:
        cx, cy = px(x, y)
        draw.ellipse([cx - MARK, cy - MARK, cx + MARK, cy + MARK], fill=COLOURS.get(variant, (0, 0, 0)))

    lx, ly = right + 20, top + 10  # legend: one colour per variant, the two marker shapes
    for variant, colour in COLOURS.items():
        draw.ellipse([lx, ly - 5, lx + 10, ly + 5], fill=colour)
        draw.text((lx + 18, ly), variant, fill="black", font=small, anchor="lm")
        ly += 22
    ly += 10
    draw.ellipse([lx, ly - 5, lx + 10, ly + 5], fill="black")
    draw.text((lx + 18, ly), "ours", fill="black", font=small, anchor="lm")
    draw.rectangle([lx, ly + 17, lx + 10, ly + 27], outline="black", width=2)
    draw.text((lx + 18, ly + 22), "paper (its data)", fill="black", font=small, anchor="lm")

    path = Path(path)
    img.save(path)
    return path
