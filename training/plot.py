"""The ablation and sweep plots: held-out PSNR against appearance size (log scale), our points next to
the paper's, and the training curves, drawn with Pillow (already a training dependency): a scatter plot
and a few lines need no plotting library."""

from __future__ import annotations

import math
from pathlib import Path

COLOURS = {"unique": (31, 119, 180), "no-card-clustering": (148, 103, 189), "single-sh": (44, 160, 44),
           "multi-sh": (255, 127, 14), "latents": (214, 39, 40)}
# a sweep's values, in order (colour-blind-safe Okabe-Ito colours)
PALETTE = ((0, 114, 178), (230, 159, 0), (0, 158, 115), (204, 121, 167), (213, 94, 0), (86, 180, 233))
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
    return plot_psnr_size([(r["variant"], r["appearance_bytes"], r["psnr"]) for r in rows],
                          [(v, mb * 1e6, psnr) for v, (psnr, mb) in paper.items()], COLOURS, path, title)


def plot_sweep(key: str, rows: list[dict], paper: dict[int, tuple[float, float]], path: str | Path,
               title: str = "") -> Path:
    """The same plot for a sweep of ``key`` (K, D or N_T): ``rows`` with ``value``, ``psnr`` and
    ``appearance_bytes``, ``paper`` value -> (PSNR, MB); one colour per value, ours and the paper's alike."""
    values = sorted({r["value"] for r in rows} | set(paper))
    colours = {f"{key} = {v}": PALETTE[i % len(PALETTE)] for i, v in enumerate(values)}
    return plot_psnr_size([(f"{key} = {r['value']}", r["appearance_bytes"], r["psnr"]) for r in rows],
                          [(f"{key} = {v}", mb * 1e6, psnr) for v, (psnr, mb) in paper.items()], colours, path, title)


def plot_psnr_size(ours: list[tuple[str, float, float]], paper: list[tuple[str, float, float]],
                   colours: dict[str, tuple[int, int, int]], path: str | Path, title: str = "",
                   size_label: str = "appearance size") -> Path:
    """Write a PNG of held-out PSNR against ``size_label`` (bytes, log scale): ``ours`` as dots and ``paper``
    as hollow squares (the shapes' legend only where there are some), each point ``(label, bytes, PSNR)``
    coloured by ``colours[label]`` (the legend)."""
    ours = [(label, math.log10(size), psnr) for label, size, psnr in ours]
    paper = [(label, math.log10(size), psnr) for label, size, psnr in paper]
    xs = [p[1] for p in ours + paper]
    x0, x1 = math.floor(min(xs) - 0.1), math.ceil(max(xs) + 0.1)  # whole decades, no point on an edge
    x1 = max(x1, x0 + 1)
    frame = _Frame((x0, x1), [p[2] for p in ours + paper], f"{size_label} (bytes, log scale)", "held-out PSNR (dB)",
                   title, [(e, _label(e)) for e in range(x0, x1 + 1)])
    for label, x, y in paper:
        cx, cy = frame.px(x, y)
        frame.draw.rectangle([cx - MARK, cy - MARK, cx + MARK, cy + MARK], outline=colours.get(label, (0, 0, 0)),
                             width=2)
    for label, x, y in ours:
        cx, cy = frame.px(x, y)
        frame.draw.ellipse([cx - MARK, cy - MARK, cx + MARK, cy + MARK], fill=colours.get(label, (0, 0, 0)))
    ly = frame.legend(colours)
    if paper:
        lx, ly = frame.right + 20, ly + 10
        frame.draw.ellipse([lx, ly - 5, lx + 10, ly + 5], fill="black")
        frame.draw.text((lx + 18, ly), "ours", fill="black", font=frame.small, anchor="lm")
        frame.draw.rectangle([lx, ly + 17, lx + 10, ly + 27], outline="black", width=2)
        frame.draw.text((lx + 18, ly + 22), "paper (its data)", fill="black", font=frame.small, anchor="lm")
    return frame.save(path)


def plot_curves(curves: dict[str, list[tuple[float, float]]], colours: dict[str, tuple[int, int, int]],
                path: str | Path, title: str = "", x_label: str = "iteration",
                y_label: str = "training-view PSNR (dB)") -> Path:
    """Write a PNG of one line a curve, ``label -> [(x, y), ...]`` (x linear), coloured by ``colours[label]``
    (the legend), e.g. the ablation's training-view PSNR against the iteration."""
    xs = [x for points in curves.values() for x, _ in points]
    x0, x1 = 0.0, max(xs)
    decade = 10.0 ** math.floor(math.log10(x1))
    step = _nice_step(x1 / decade) * decade
    ticks = [(t * step, f"{t * step:g}") for t in range(int(x1 // step) + 1)]
    frame = _Frame((x0, x1), [y for points in curves.values() for _, y in points], x_label, y_label, title, ticks)
    for label, points in curves.items():
        line = [frame.px(x, y) for x, y in points]
        frame.draw.line(line, fill=colours.get(label, (0, 0, 0)), width=3)
    frame.legend({label: colours.get(label, (0, 0, 0)) for label in curves})
    return frame.save(path)


class _Frame:
    """A white image with a framed plot area over ``xr`` (x0, x1) and the y range ``ys`` spans, grid lines at
    ``x_ticks`` (value, label) and at round y values, axis labels and a title; :meth:`px` maps data to pixels."""

    def __init__(self, xr: tuple[float, float], ys: list[float], x_label: str, y_label: str, title: str,
                 x_ticks: list[tuple[float, str]]):
        from PIL import Image, ImageDraw, ImageFont

        self.x0, self.x1 = xr
        step = _nice_step(max(ys) - min(ys) + 1)
        self.y0, self.y1 = step * math.floor((min(ys) - 0.5) / step), step * math.ceil((max(ys) + 0.5) / step)
        self.img = Image.new("RGB", SIZE, "white")
        self.draw = draw = ImageDraw.Draw(self.img)
        font, self.small = ImageFont.load_default(size=15), ImageFont.load_default(size=12)
        left, top, right, bottom = self.left, self.top, self.right, self.bottom = (
            MARGIN[0], MARGIN[1], SIZE[0] - MARGIN[2], SIZE[1] - MARGIN[3])
        for value, label in x_ticks:
            gx = self.px(value, self.y0)[0]
            draw.line([(gx, top), (gx, bottom)], fill=(225, 225, 225))
            draw.text((gx, bottom + 8), label, fill="black", font=self.small, anchor="mt")
        y = self.y0
        while y <= self.y1 + 1e-9:
            gy = self.px(self.x0, y)[1]
            draw.line([(left, gy), (right, gy)], fill=(225, 225, 225))
            draw.text((left - 8, gy), f"{y:g}", fill="black", font=self.small, anchor="rm")
            y += step
        draw.rectangle([left, top, right, bottom], outline="black")
        draw.text(((left + right) / 2, SIZE[1] - 20), x_label, fill="black", font=font, anchor="mm")
        rotated = Image.new("RGB", (bottom - top, 24), "white")
        ImageDraw.Draw(rotated).text(((bottom - top) / 2, 12), y_label, fill="black", font=font, anchor="mm")
        self.img.paste(rotated.rotate(90, expand=True), (12, top))
        if title:
            draw.text(((left + right) / 2, top / 2), title, fill="black", font=font, anchor="mm")

    def px(self, x: float, y: float) -> tuple[float, float]:
        return (self.left + (x - self.x0) / (self.x1 - self.x0) * (self.right - self.left),
                self.bottom - (y - self.y0) / (self.y1 - self.y0) * (self.bottom - self.top))

    def legend(self, colours: dict[str, tuple[int, int, int]]) -> int:
        """One colour a label right of the plot area; returns the y below it."""
        lx, ly = self.right + 20, self.top + 10
        for label, colour in colours.items():
            self.draw.ellipse([lx, ly - 5, lx + 10, ly + 5], fill=colour)
            self.draw.text((lx + 18, ly), label, fill="black", font=self.small, anchor="lm")
            ly += 22
        return ly

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        self.img.save(path)
        return path
