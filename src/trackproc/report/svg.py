"""Small SVG figures written as text, for pages that embed them inline (``report.html``).

Scatter panels only: one marker per value, a linear or a decade (log) value axis with ticks at
1-2-5 steps or at powers of ten, a legend beside the axes, category or index labels on the x
axis. Pure Python (no matplotlib, no numpy): a figure of a thousand markers is a few milliseconds
of CPU. Text from the data is escaped; the ``<svg>`` carries no namespace URL (inline SVG in
HTML5 needs none) and no external reference.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

#: matplotlib's first colours (C0, C1, C2), so the page looks like the other figures.
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c")
MARKERS = ("circle", "square", "triangle")
FONT = "DejaVu Sans,Helvetica,Arial,sans-serif"


def escape(text) -> str:
    """``text`` for an SVG attribute or text node."""
    return html.escape(str(text), quote=True)


def _f(value: float) -> str:
    """A pixel coordinate (two decimals: far below a pixel, short text)."""
    return f"{value:.2f}"


def nice_step(span: float, most: int = 6) -> float:
    """The smallest step of 1, 2 or 5 times a power of ten giving at most ``most`` intervals over
    ``span`` (the usual axis-tick rule)."""
    raw = span / most
    power = 10.0 ** math.floor(math.log10(raw))
    for factor in (1.0, 2.0, 5.0, 10.0):
        if factor * power >= raw * (1 - 1e-12):
            return factor * power
    return 10.0 * power  # not reached


def _decimals(step: float) -> int:
    return max(0, -math.floor(math.log10(step) + 1e-9))


@dataclass
class Scale:
    """Value -> pixel along one axis: linear, or linear in log10 of the value (``log``)."""

    lo: float
    hi: float
    p0: float  # pixel of lo
    p1: float  # pixel of hi
    log: bool = False
    ticks: list = field(default_factory=list)
    labels: list = field(default_factory=list)

    def __call__(self, value: float) -> float:
        f = (math.log10 if self.log else float)
        a, b = f(self.lo), f(self.hi)
        return self.p0 + (f(value) - a) * (self.p1 - self.p0) / (b - a)


def value_scale(values: Sequence[float], p0: float, p1: float, log: bool) -> Scale:
    """The value axis over ``values`` (finite ones; positive ones on a log axis): a log axis from
    the decade below the least to the decade above the greatest, ticks at each power of ten; a
    linear axis widened to whole 1-2-5 steps, ticks at each step."""
    if log:
        lo = math.floor(math.log10(min(values)))
        hi = math.ceil(math.log10(max(values)))
        hi = max(hi, lo + 1)
        ticks = [10.0 ** k for k in range(lo, hi + 1)]
        return Scale(ticks[0], ticks[-1], p0, p1, True, ticks, [f"{t:g}" for t in ticks])
    lo, hi = min(values), max(values)
    if hi - lo <= 1e-12 * max(abs(lo), abs(hi), 1e-300):  # one value: a span around it
        pad = abs(lo) * 0.1 or 1.0
        lo, hi = lo - pad, hi + pad
    step = nice_step(hi - lo)
    first, last = math.floor(lo / step + 1e-9), math.ceil(hi / step - 1e-9)
    ticks = [k * step for k in range(first, last + 1)]
    digits = _decimals(step)
    return Scale(ticks[0], ticks[-1], p0, p1, False, ticks, [f"{t:.{digits}f}" for t in ticks])


def marker(kind: str, x: float, y: float, color: str, size: float = 4.0) -> str:
    """One marker centred on (x, y): a circle, a square or a triangle (its vertices' mean is the
    centre)."""
    if kind == "circle":
        return f'<circle cx="{_f(x)}" cy="{_f(y)}" r="{_f(size / 2 + 0.5)}" fill="{color}"/>'
    if kind == "square":
        h = size / 2
        return f'<rect x="{_f(x - h)}" y="{_f(y - h)}" width="{_f(size)}" height="{_f(size)}" fill="{color}"/>'
    r = size * 0.65
    points = " ".join(f"{_f(x + r * math.sin(a))},{_f(y - r * math.cos(a))}"
                      for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3))
    return f'<polygon points="{points}" fill="{color}"/>'


def _text(x: float, y: float, text, size: float = 10, anchor: str = "start", rotate: Optional[float] = None,
          cls: str = "", baseline: str = "") -> str:
    attrs = f' class="{cls}"' if cls else ""
    if rotate is not None:
        attrs += f' transform="rotate({rotate:g} {_f(x)} {_f(y)})"'
    if baseline:
        attrs += f' dominant-baseline="{baseline}"'
    return (f'<text x="{_f(x)}" y="{_f(y)}" font-size="{size:g}" text-anchor="{anchor}"{attrs}>'
            f"{escape(text)}</text>")


@dataclass
class Series:
    label: str
    values: Sequence[Optional[float]]  # one per x position; None or NaN: no marker


@dataclass
class Panel:
    ylabel: str
    series: list
    log: Optional[bool] = None  # None: log where the positive values span more than a decade

    def finite(self) -> list:
        return [v for s in self.series for v in s.values if v is not None and math.isfinite(v)]

    def is_log(self) -> bool:
        if self.log is not None:
            return self.log
        positive = [v for v in self.finite() if v > 0]
        return bool(positive) and max(positive) > 10 * min(positive)


def _width(text: str, size: float) -> float:
    """A text's width estimate (0.6 em a character: wide enough for the usual sans fonts)."""
    return 0.6 * size * len(text)


def scatter_panels(panels: Sequence[Panel], names: Sequence[str], title: str = "", *, width: int = 1000,
                   panel_height: int = 230, max_named: int = 60, xlabel: str = "") -> str:
    """Panels stacked over a shared x axis (position i for ``names[i]``): the bottom axis labels
    each position with its name when there are at most ``max_named`` of them, else ticks at
    indices and ``xlabel``. Returns the ``<svg>`` element."""
    n = len(names)
    named = n <= max_named
    left, legend_w, gap = 72.0, max(110.0, max((_width(s.label, 9) for p in panels for s in p.series),
                                               default=0) + 40), 14.0
    top = 28.0 if title else 10.0
    bottom = (min(max((len(str(nm)) for nm in names), default=1), 48) * 5.4 + 16) if named else 44.0
    right = width - legend_w
    height = top + len(panels) * panel_height + (len(panels) - 1) * gap + bottom
    xs = Scale(-0.5, n - 0.5, left, right)
    out = [f'<svg class="figure" width="{width}" height="{_f(height)}" viewBox="0 0 {width} {_f(height)}" '
           f'font-family="{FONT}" role="img" aria-label="{escape(title)}">',
           f'<rect x="0" y="0" width="{width}" height="{_f(height)}" fill="#fff"/>']
    if title:
        out.append(_text((left + right) / 2, 18, title, 12, "middle", cls="title"))
    for k, panel in enumerate(panels):
        y0 = top + k * (panel_height + gap)
        y1 = y0 + panel_height
        values = panel.finite()
        log = panel.is_log()
        if log:
            values = [v for v in values if v > 0]
        ys = value_scale(values, y1, y0, log)
        out.append(f'<g class="panel" data-scale="{"log" if log else "linear"}">')
        out.append('<g class="yticks" stroke="#e6e6e6">')
        for t in ys.ticks:
            y = ys(t)
            out.append(f'<line x1="{_f(left)}" x2="{_f(right)}" y1="{_f(y)}" y2="{_f(y)}"/>')
        out.append("</g>")
        for t, label in zip(ys.ticks, ys.labels):
            out.append(_text(left - 5, ys(t), label, 9, "end", cls="ytick", baseline="middle"))
        out.append(_text(16, (y0 + y1) / 2, panel.ylabel, 9, "middle", rotate=-90, cls="ylabel"))
        out.append(f'<rect x="{_f(left)}" y="{_f(y0)}" width="{_f(right - left)}" height="{_f(panel_height)}" '
                   f'fill="none" stroke="#444"/>')
        legend = []
        for j, s in enumerate(panel.series):
            color, kind = COLORS[j % len(COLORS)], MARKERS[j % len(MARKERS)]
            out.append(f'<g class="series" data-label="{escape(s.label)}" data-marker="{kind}">')
            for i, v in enumerate(s.values):
                if v is None or not math.isfinite(v) or (log and v <= 0):
                    continue
                out.append(marker(kind, xs(i), ys(v), color))
            out.append("</g>")
            ly = y0 + 14 + 16 * j
            legend.append(marker(kind, right + 18, ly, color))
            legend.append(_text(right + 28, ly, s.label, 9, cls="legend", baseline="middle"))
        out.append('<g class="legend">' + "".join(legend) + "</g>")
        out.append("</g>")
    y1 = top + len(panels) * (panel_height + gap) - gap
    if named:
        for i, name in enumerate(names):
            out.append(_text(xs(i), y1 + 6, name, 8, "end", rotate=-90, cls="xtick", baseline="middle"))
    else:
        step = max(1.0, nice_step(n - 1 or 1, 10))
        for t in range(0, n, int(step)):
            out.append(_text(xs(t), y1 + 14, str(t), 9, "middle", cls="xtick"))
        out.append(_text((left + right) / 2, y1 + 34, xlabel, 10, "middle", cls="xlabel"))
    out.append("</svg>")
    return "\n".join(out)
