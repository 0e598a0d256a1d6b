"""report.html's overview figure, an inline SVG written as text (report/svg.py): parsed back with
xml.etree, each marker's pixel position is mapped through the axis that its tick labels and their
positions define (linear, or linear in log10) and must give the input's value; names are the x
tick labels, in order and escaped."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import pytest

from trackproc.report.batch_html import overview_svg, report_html


def _records(n=12, **override):
    records = []
    for i in range(n):
        numbers = {"kind": "doppler", "rms": 0.2 + 0.01 * i, "rms_unit": "Hz", "residual_rms": 0.3 + 0.002 * i,
                   "residual_rms_unit": "Hz", "sigma_radial_m": 10.0 * (i + 1), "sigma_along_m": 300.0 + i,
                   "sigma_cross_m": 5000.0 - 7 * i}
        numbers.update({k: v(i) for k, v in override.items()})
        records.append({"task": "pass", "name": f"pass-{i:02d}", "status": "ok", "numbers": numbers})
    return records


def _center(el):
    if el.tag == "circle":
        return float(el.get("cx")), float(el.get("cy"))
    if el.tag == "rect":
        return float(el.get("x")) + float(el.get("width")) / 2, float(el.get("y")) + float(el.get("height")) / 2
    points = [tuple(map(float, p.split(","))) for p in el.get("points").split()]
    return sum(p[0] for p in points) / len(points), sum(p[1] for p in points) / len(points)


def _panels(svg: str):
    root = ET.fromstring(svg)  # well-formed XML (escaping included)
    return root, root.findall("g[@class='panel']")


def _axis(panel):
    """The value <- pixel map the panel's tick labels define: two ticks fix it; every other tick
    must lie on it."""
    ticks = [(float(t.text), float(t.get("y"))) for t in panel.findall("text[@class='ytick']")]
    log = panel.get("data-scale") == "log"
    f = math.log10 if log else float
    (v0, y0), (v1, y1) = ticks[0], ticks[-1]
    per_px = (f(v1) - f(v0)) / (y1 - y0)

    def value(y):
        u = f(v0) + (y - y0) * per_px
        return 10 ** u if log else u

    for v, y in ticks:  # on the line within the coordinates' rounding (0.005 px)
        assert f(v0) + (y - y0) * per_px == pytest.approx(f(v), abs=abs(per_px) * 0.011)
    return [v for v, _ in ticks], value, per_px


def _series(panel):
    return {g.get("data-label"): [_center(m) for m in g] for g in panel.findall("g[@class='series']")}


def _xticks(root):
    return [(t.text, float(t.get("x"))) for t in root.findall("text[@class='xtick']")]


def test_fit_panel_is_linear_with_1_2_5_ticks_and_markers_at_the_values():
    records = _records()
    root, panels = _panels(overview_svg(records))
    assert len(panels) == 3
    fit = panels[0]
    assert fit.get("data-scale") == "linear"  # 0.2 .. 0.31: less than a decade
    ticks, value, per_px = _axis(fit)
    steps = {round(b - a, 12) for a, b in zip(ticks, ticks[1:])}
    assert len(steps) == 1
    step = steps.pop()
    mantissa = step / 10 ** math.floor(math.log10(step))
    assert round(mantissa, 9) in (1.0, 2.0, 5.0) and 3 <= len(ticks) <= 8
    assert ticks[0] <= 0.2 and ticks[-1] >= 0.31
    names = _xticks(root)
    assert [n for n, _ in names] == [r["name"] for r in records]
    (label, markers), = _series(fit).items()
    assert label == "doppler" and len(markers) == len(records)
    half_px = abs(per_px) * 0.01
    for (x, y), (_, tick_x), r in zip(markers, names, records):
        assert x == pytest.approx(tick_x, abs=0.01)
        assert value(y) == pytest.approx(r["numbers"]["rms"], abs=half_px)
    assert "smoothing fit RMS [Hz]" in [t.text for t in fit.findall("text[@class='ylabel']")]


def test_sigma_panel_is_log_with_decade_ticks_three_marker_kinds_and_gaps():
    records = _records(sigma_along_m=lambda i: None if i == 3 else 300.0 + i)
    root, panels = _panels(overview_svg(records))
    sigma = panels[2]
    assert sigma.get("data-scale") == "log"  # 10 .. 5000
    ticks, value, _ = _axis(sigma)
    assert ticks == [10.0 ** k for k in range(1, 5)]
    series = _series(sigma)
    assert list(series) == ["radial", "along-track", "cross-track"]
    kinds = {g.get("data-label"): (g.get("data-marker"), g[0].tag) for g in sigma.findall("g[@class='series']")}
    assert kinds == {"radial": ("circle", "circle"), "along-track": ("square", "rect"),
                     "cross-track": ("triangle", "polygon")}
    xs = [x for _, x in _xticks(root)]
    for label, key in (("radial", "sigma_radial_m"), ("along-track", "sigma_along_m"),
                       ("cross-track", "sigma_cross_m")):
        expected = [(xs[i], r["numbers"][key]) for i, r in enumerate(records) if r["numbers"][key] is not None]
        assert len(series[label]) == len(expected)  # the missing value has no marker
        for (x, y), (tick_x, v) in zip(series[label], expected):
            assert x == pytest.approx(tick_x, abs=0.01)
            assert value(y) == pytest.approx(v, rel=2e-4)
    legend = [t.text for t in sigma.findall("g[@class='legend']/text")]
    assert legend == ["radial", "along-track", "cross-track"]


def test_residual_panel_one_value_escaped_names_and_the_index_axis():
    name = 'a<b>&"c'
    records = _records(3, residual_rms=lambda i: 0.5)
    records[1]["name"] = name
    records.append({"task": "pass", "name": "broken", "status": "failed", "numbers": {}})
    svg = overview_svg(records)
    assert name not in svg and "a&lt;b&gt;&amp;&quot;c" in svg
    root, panels = _panels(svg)
    assert [n for n, _ in _xticks(root)] == ["pass-00", name, "pass-02"]  # the failed input left out
    residual = panels[1]
    assert residual.get("data-scale") == "linear"
    _, value, per_px = _axis(residual)
    (label, markers), = _series(residual).items()
    assert label == "residual RMS" and len(markers) == 3
    assert all(value(y) == pytest.approx(0.5, abs=abs(per_px) * 0.01) for _, y in markers)
    # beyond 60 inputs: no names, an index axis with its label
    many = _records(75)
    root, panels = _panels(overview_svg(many))
    assert all(t.text.isdigit() for t in root.findall("text[@class='xtick']"))
    assert "75 processed inputs" in root.find("text[@class='xlabel']").text
    assert len(_series(panels[0])["doppler"]) == 75


def test_no_figure_without_numbers_and_the_page_draws_it_without_matplotlib(tmp_path):
    assert overview_svg([{"task": "pass", "name": "x", "status": "failed", "numbers": {}}]) is None
    assert overview_svg([{"task": "pass", "name": "x", "status": "ok", "numbers": {"samples": 3}}]) is None
    summary = {"started_utc": "2026-01-01T00:00:00Z", "counts": {"inputs": 12}, "exit_code": 0,
               "inputs": _records(), "estimates": []}
    text = report_html(summary, tmp_path, plots=False)
    start = text.index("<svg")
    svg = text[start:text.index("</svg>", start) + len("</svg>")]
    root, panels = _panels(svg)
    assert len(panels) == 3 and "http" not in svg and "<img" not in text
