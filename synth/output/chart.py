"""A small chart painter on Pillow: line and step charts, rose diagrams, titles and legends.

The evaluation plots (:mod:`texsynth.synth.output.plots`) need a handful of chart elements, and a synthesis
writes them every run: matplotlib took longer to import (0.4-0.7 s on the project's machine) than the
whole evaluation, and 1.5 s to draw five figures. Here a chart is painted with Pillow at twice its
size and halved with a box filter, which smooths lines and text like an anti-aliased renderer, in a
few milliseconds. Sizes are in output pixels (a 640 x 400 chart is a 640 x 400 PNG); the text is
Pillow's default font, as in the legends of :mod:`texsynth.synth.output.render`.

Only what the plots use: :class:`Chart` (a canvas of panels, a title, :meth:`Chart.save`),
:class:`Axes` (``stairs``, ``plot``, ``axvline``, ``axhline``, labels, ``legend``) and :class:`Rose`
(petals over 360 degrees, the angle grid every 45 degrees).
"""

from __future__ import annotations

import itertools
import math
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from texsynth.synth.io import PICTURE_PNG_LEVEL, atomic_write_bytes

__all__ = ["Axes", "Chart", "Rose", "hex_colour", "nice_ticks"]

_SS = 2  # supersampling factor
_PT = 100 / 72  # font sizes, line widths and dashes are in points, as matplotlib's, at 100 dpi
_TEXT = (0, 0, 0)
_FRAME = (0, 0, 0)
_GRID = (176, 176, 176)
_WHITE = (255, 255, 255)
Colour = tuple[int, int, int]


def hex_colour(colour: str | Sequence[float]) -> Colour:
    """``'#1f4e9a'`` or an RGB triple in [0, 1] -> an 8-bit RGB triple."""
    if isinstance(colour, str):
        h = colour.lstrip("#")
        return int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16)
    r, g, b = (round(255 * float(c)) for c in colour[:3])
    return r, g, b


_fonts: dict[int, ImageFont.FreeTypeFont | ImageFont.ImageFont] = {}


def _font(size: float) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    px = max(1, round(size * _PT * _SS))
    if px not in _fonts:
        _fonts[px] = ImageFont.load_default(size=px)
    return _fonts[px]


def nice_ticks(lo: float, hi: float, most: int = 7) -> list[float]:
    """Round tick values (steps 1, 2, 2.5 or 5 times a power of ten) covering ``[lo, hi]``."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    raw = (hi - lo) / max(most - 1, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * power >= raw * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9)
    ticks = [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]
    return [0.0 if abs(t) < step * 1e-9 else t for t in ticks]


def _tick_label(value: float, ticks: Sequence[float]) -> str:
    step = abs(ticks[1] - ticks[0]) if len(ticks) > 1 else abs(value) or 1.0
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    if decimals and round(step * 10**decimals) % 10 == 5 and step * 10**decimals < 1:
        decimals += 1
    if abs(step * 10**decimals - round(step * 10**decimals)) > 1e-6:
        decimals += 1
    return f"{value:.{decimals}f}"


class Chart:
    """A white canvas of ``width`` x ``height`` output pixels, painted at twice the size."""

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height = int(width), int(height)
        self.image = Image.new("RGB", (self.width * _SS, self.height * _SS), _WHITE)
        self.draw = ImageDraw.Draw(self.image, "RGBA")

    # -- primitives in output pixels --------------------------------------------------------------
    def text(
        self,
        xy: tuple[float, float],
        text: str,
        size: float = 10,
        anchor: str = "la",
        colour: Colour = _TEXT,
    ) -> None:
        """One line of text; ``anchor`` as Pillow's (``'mm'`` centred, ``'ra'`` right-top, ...)."""
        x, y = xy
        self.draw.text((x * _SS, y * _SS), text, fill=colour, font=_font(size), anchor=anchor)

    def lines(
        self, xy: tuple[float, float], lines: Sequence[str], size: float = 10, align: str = "m"
    ) -> float:
        """Lines of text centred (``align='m'``) or left-aligned (``'l'``) from ``xy`` down; returns
        the y below them."""
        x, y = xy
        step = size * _PT * 1.25
        for line in lines:
            self.text((x, y), line, size, anchor=f"{align}a" if align != "m" else "ma")
            y += step
        return y

    def text_width(self, text: str, size: float = 10) -> float:
        left, _, right, _ = _font(size).getbbox(text)
        return (right - left) / _SS

    def vertical_text(self, xy: tuple[float, float], text: str, size: float = 10) -> None:
        """Text read bottom to top, centred on ``xy``."""
        font = _font(size)
        left, top, right, bottom = font.getbbox(text)
        label = Image.new("L", (right - left + 2, bottom - top + 2), 0)
        ImageDraw.Draw(label).text((1 - left, 1 - top), text, fill=255, font=font)
        label = label.rotate(90, expand=True)
        x, y = xy
        pos = (round(x * _SS - label.width / 2), round(y * _SS - label.height / 2))
        self.image.paste(Image.new("RGB", label.size, _TEXT), pos, label)

    def polyline(
        self,
        points: np.ndarray,
        colour: Colour,
        width: float = 1.0,
        dash: tuple[float, float] | None = None,
    ) -> None:
        """A polyline through ``points`` (``(n, 2)`` output pixels), ``width`` points wide, solid or
        dashed: ``dash = (on, off)`` in multiples of the width (matplotlib's ``'--'`` is ``(3.7, 1.6)``)."""
        pts = np.asarray(points, dtype=np.float64) * _SS
        w = max(1, round(width * _PT * _SS))
        if dash is None:
            self.draw.line([tuple(p) for p in pts], fill=colour, width=w, joint="curve")
            return
        on, off = (max(1.0, d * width * _PT * _SS) for d in dash)
        for segment in _dashes(pts, on, off):
            self.draw.line([tuple(p) for p in segment], fill=colour, width=w)

    def title(self, text: str | Sequence[str], size: float = 10, top: float = 4) -> float:
        """A title centred at the top (a string is wrapped to the width); returns the y below it."""
        lines = self._wrap(text, size, self.width - 16)
        return self.lines((self.width / 2, top), lines, size)

    def _wrap(self, text: str | Sequence[str], size: float, width: float) -> list[str]:
        raw = text.split("\n") if isinstance(text, str) else list(text)
        per_line = max(20, int(width / (0.55 * size)))
        return [w for line in raw for w in (textwrap.wrap(line, per_line) or [""])]

    # -- output ------------------------------------------------------------------------------------
    def to_image(self) -> Image.Image:
        return self.image.reduce(_SS)

    def save(self, path: str | Path) -> Path:
        """Write the chart as a PNG (atomically)."""
        import io

        path = Path(path)
        buffer = io.BytesIO()
        self.to_image().save(buffer, format="PNG", compress_level=PICTURE_PNG_LEVEL)
        atomic_write_bytes(path, buffer.getvalue())
        return path


def _dashes(points: np.ndarray, on: float, off: float) -> list[list[np.ndarray]]:
    """Split a polyline into dash segments of length ``on`` separated by gaps ``off``."""
    segments: list[list[np.ndarray]] = []
    current: list[np.ndarray] = []
    drawing, left = True, on
    for a, b in itertools.pairwise(points):
        length = float(np.hypot(*(b - a)))
        pos = 0.0
        while length - pos > 1e-9:
            step = min(left, length - pos)
            p0 = a + (b - a) * (pos / length)
            p1 = a + (b - a) * ((pos + step) / length)
            if drawing:
                if not current:
                    current.append(p0)
                current.append(p1)
            pos += step
            left -= step
            if left <= 1e-9:
                if drawing and current:
                    segments.append(current)
                    current = []
                drawing = not drawing
                left = on if drawing else off
    if current:
        segments.append(current)
    return segments


_LEGEND_LINE = 22


class Axes:
    """A rectangular plot panel: the frame ``box = (left, top, right, bottom)`` in output pixels."""

    def __init__(self, chart: Chart, box: tuple[float, float, float, float]) -> None:
        self.chart = chart
        self.box = box
        self.artists: list[tuple[str, tuple]] = []
        self.legend_entries: list[tuple[str, Colour, float, tuple[float, float] | None]] = []
        self.xlim: tuple[float, float] | None = None
        self.ylim: tuple[float | None, float | None] = (None, None)
        self.title_text: str = ""
        self.title_size = 9.0
        self.xlabel = ""
        self.ylabel = ""
        self._data_x: list[float] = []
        self._data_y: list[float] = []
        self.baseline = False

    # -- artists (drawn by finish) ----------------------------------------------------------------
    def stairs(self, values, edges, *, colour, width=1.5, dash=None, label=None) -> None:
        v = np.asarray(values, dtype=np.float64)
        e = np.asarray(edges, dtype=np.float64)
        # closed down to the zero baseline at both ends, as matplotlib's ``stairs``
        x = np.repeat(e, 2)
        y = np.concatenate([[0.0], np.repeat(v, 2), [0.0]])
        self.baseline = True
        self._line(x, y, colour, width, dash, label)

    def plot(self, x, y, *, colour, width=1.5, dash=None, label=None) -> None:
        self._line(np.asarray(x, np.float64), np.asarray(y, np.float64), colour, width, dash, label)

    def _line(self, x, y, colour, width, dash, label) -> None:
        keep = np.isfinite(x) & np.isfinite(y)
        self.artists.append(("line", (x[keep], y[keep], colour, width, dash)))
        self._data_x += [float(x[keep].min()), float(x[keep].max())] if keep.any() else []
        self._data_y += [float(y[keep].min()), float(y[keep].max())] if keep.any() else []
        if label:
            self.legend_entries.append((label, colour, width, dash))

    def axvline(self, x, *, colour, width=0.8, dash=(1.5, 2.5), label=None) -> None:
        self.artists.append(("vline", (float(x), colour, width, dash)))
        if label:
            self.legend_entries.append((label, colour, width, dash))

    def axhline(self, y, *, colour, width=0.8, dash=(1.5, 2.5), label=None) -> None:
        self.artists.append(("hline", (float(y), colour, width, dash)))
        self._data_y.append(float(y))
        if label:
            self.legend_entries.append((label, colour, width, dash))

    # -- scales -----------------------------------------------------------------------------------
    def _limits(self) -> tuple[float, float, float, float]:
        xs = self._data_x or [0.0, 1.0]
        x0, x1 = self.xlim if self.xlim is not None else (min(xs), max(xs))
        if x1 <= x0:
            x0, x1 = x0 - 0.5, x1 + 0.5
        if self.xlim is None:  # matplotlib's 5% margins
            pad = 0.05 * (x1 - x0)
            x0, x1 = x0 - pad, x1 + pad
        ys = self._data_y or [0.0, 1.0]
        y0, y1 = min(ys), max(ys)
        if y1 <= y0:
            y0, y1 = y0 - 0.5, y1 + 0.5
        pad = 0.05 * (y1 - y0)
        # histograms stand on zero (matplotlib's sticky baseline of ``stairs``)
        y0, y1 = (y0 if y0 == 0.0 and self.baseline else y0 - pad), y1 + pad
        lo, hi = self.ylim
        return x0, x1, (lo if lo is not None else y0), (hi if hi is not None else y1)

    def finish(self, legend: str | None = "upper right") -> None:
        """Draw the grid-free frame, ticks, artists, labels and the legend."""
        c = self.chart
        left, top, right, bottom = self.box
        x0, x1, y0, y1 = self._limits()

        def px(x):
            return left + (np.asarray(x, np.float64) - x0) / (x1 - x0) * (right - left)

        def py(y):
            return bottom - (np.asarray(y, np.float64) - y0) / (y1 - y0) * (bottom - top)

        for kind, args in self.artists:
            if kind == "line":
                x, y, colour, width, dash = args
                if len(x):
                    pts = np.stack([px(x), py(y)], axis=1)
                    pts[:, 0] = np.clip(pts[:, 0], left, right)
                    pts[:, 1] = np.clip(pts[:, 1], top, bottom)
                    c.polyline(pts, colour, width, dash)
            elif kind == "vline":
                x, colour, width, dash = args
                if x0 <= x <= x1:
                    c.polyline(np.array([[px(x), top], [px(x), bottom]]), colour, width, dash)
            else:
                y, colour, width, dash = args
                if y0 <= y <= y1:
                    c.polyline(np.array([[left, py(y)], [right, py(y)]]), colour, width, dash)
        frame = np.array([[left, top], [right, top], [right, bottom], [left, bottom], [left, top]])
        c.polyline(frame, _FRAME, 0.8)
        size = 9.0
        xticks = [t for t in nice_ticks(x0, x1, 7) if x0 - 1e-9 <= t <= x1 + 1e-9]
        for t in xticks:
            x = float(px(t))
            c.polyline(np.array([[x, bottom], [x, bottom + 3.5]]), _FRAME, 0.8)
            c.text((x, bottom + 5), _tick_label(t, xticks), size, anchor="ma")
        yticks = [t for t in nice_ticks(y0, y1, 8) if y0 - 1e-9 <= t <= y1 + 1e-9]
        widest = 0.0
        for t in yticks:
            y = float(py(t))
            label = _tick_label(t, yticks)
            widest = max(widest, c.text_width(label, size))
            c.polyline(np.array([[left - 3.5, y], [left, y]]), _FRAME, 0.8)
            c.text((left - 5, y), label, size, anchor="rm")
        if self.xlabel:
            c.text(((left + right) / 2, bottom + 22), self.xlabel, 10, anchor="ma")
        if self.ylabel:
            c.vertical_text((left - widest - 16, (top + bottom) / 2), self.ylabel, 10)
        if self.title_text:
            lines = c._wrap(self.title_text, self.title_size, right - left + 40)
            height = len(lines) * self.title_size * _PT * 1.25
            c.lines(((left + right) / 2, top - height - 4), lines, self.title_size)
        if legend and self.legend_entries:
            self._legend(legend)

    def _legend(self, where: str) -> None:
        c = self.chart
        left, top, right, bottom = self.box
        size = 7.5
        width = max(c.text_width(label, size) for label, *_ in self.legend_entries) + _LEGEND_LINE + 16
        height = len(self.legend_entries) * size * _PT * 1.5 + 8
        x = right - width - 6 if "right" in where else left + 6
        y = top + 6 if "upper" in where else bottom - height - 6
        c.draw.rectangle(
            [x * _SS, y * _SS, (x + width) * _SS, (y + height) * _SS],
            fill=(255, 255, 255, 215),
            outline=(204, 204, 204),
            width=_SS,
        )
        for i, (label, colour, width_line, dash) in enumerate(self.legend_entries):
            yy = y + 4 + (i + 0.5) * size * _PT * 1.5
            c.polyline(np.array([[x + 5, yy], [x + 5 + _LEGEND_LINE, yy]]), colour, width_line, dash)
            c.text((x + 10 + _LEGEND_LINE, yy), label, size, anchor="lm")


class Rose:
    """A rose diagram: petals of a 180-degree histogram drawn twice (mirrored), angles every 45 degrees.

    ``centre`` and ``radius`` in output pixels; 0 degrees to the right, counter-clockwise (y up).
    """

    def __init__(self, chart: Chart, centre: tuple[float, float], radius: float) -> None:
        self.chart, self.centre, self.radius = chart, centre, radius

    def draw(
        self, hist: Sequence[float], colour: Colour, title: str | Sequence[str], alpha: float = 0.75
    ) -> None:
        c = self.chart
        cx, cy = self.centre
        r = self.radius
        h = np.asarray(hist, dtype=np.float64)
        n = len(h)
        top = float(h.max()) if h.size and h.max() > 0 else 1.0
        rmax = 1.05 * top
        ticks = nice_ticks(0.0, rmax, 5)
        # grid: circles and rays every 45 degrees, below the petals
        for t in ticks[1:]:
            rr = r * t / rmax
            c.draw.ellipse(
                [(cx - rr) * _SS, (cy - rr) * _SS, (cx + rr) * _SS, (cy + rr) * _SS], outline=_GRID, width=_SS
            )
        for k in range(8):
            a = math.radians(45 * k)
            c.polyline(np.array([[cx, cy], [cx + r * math.cos(a), cy - r * math.sin(a)]]), _GRID, 0.5)
        fill = (*colour, round(255 * alpha))
        width = math.pi / n
        # gradient-orientation bin centres, plus 90 degrees: the fringe direction
        centres = -math.pi / 2 + width * (np.arange(n) + 0.5) + math.pi / 2
        for shift in (0.0, math.pi):
            for value, centre in zip(h, centres + shift, strict=True):
                if value <= 0:
                    continue
                rr = r * value / rmax
                angles = np.linspace(centre - width / 2, centre + width / 2, 6)
                pts = [(cx * _SS, cy * _SS)] + [
                    ((cx + rr * math.cos(a)) * _SS, (cy - rr * math.sin(a)) * _SS) for a in angles
                ]
                c.draw.polygon(pts, fill=fill, outline=_WHITE)
        c.draw.ellipse(
            [(cx - r) * _SS, (cy - r) * _SS, (cx + r) * _SS, (cy + r) * _SS], outline=_FRAME, width=_SS
        )
        for k in range(8):
            a = math.radians(45 * k)
            x, y = cx + (r + 13) * math.cos(a), cy - (r + 13) * math.sin(a)
            c.text((x, y), f"{45 * k}°", 7, anchor="mm")
        lines = c._wrap(title, 9, 2 * r + 60)
        c.lines((cx, cy - r - 24 - len(lines) * 9 * _PT * 1.25), lines, 9)
