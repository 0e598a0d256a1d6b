"""Report figures (issue 16): residuals per kind in their own units (degrees for angles) with the
RMS of each pass, checked against numpy on a frame whose residuals are known.

Every figure a command draws is checked as it is saved (``laid_out``): the image has a sensible
size, and no text (title, axis label, tick label, legend) reaches past the figure's edges, by the
figure's own renderer; legends sit outside the axes; lines break at data gaps."""

import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("matplotlib")

from trackproc.report import plots  # noqa: E402
from trackproc.report.plots import break_gaps, residuals_png, rms_by_pass  # noqa: E402

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"


def clipped_texts(fig) -> list:
    """Texts of ``fig`` whose window extent (by the figure's renderer) is not inside the figure's
    bounding box (1 px of slack): each axes' tight box (its drawn tick labels, axis labels, title,
    legend) and every other visible text (suptitle, figure legends, annotations)."""
    from matplotlib.text import Text

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    extents = []
    ticks = set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            ticks.update(id(t) for t in axis.get_ticklabels(which="both"))
            ticks.update(id(t) for t in (axis.get_offset_text(),))
        if ax.get_visible():
            extents.append((f"axes {ax.get_title()!r} with its labels and legend", ax.get_tightbbox(renderer)))
    for text in fig.findobj(Text):
        if id(text) in ticks or not text.get_visible() or not text.get_text().strip():
            continue
        extents.append((text.get_text()[:60], text.get_window_extent(renderer)))
    return [(name, tuple(round(v) for v in e.extents)) for name, e in extents if e is not None and (
        e.x0 < box.x0 - 1 or e.y0 < box.y0 - 1 or e.x1 > box.x1 + 1 or e.y1 > box.y1 + 1)]


def legends_inside_axes(fig, drawn: bool = False) -> list:
    """Axes legends that overlap their axes' data area (they belong outside). ``drawn``: the figure
    was just drawn (by :func:`clipped_texts`) and has not changed since: its layout is read as is."""
    if not drawn:
        fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    out = []
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is not None and legend.get_visible():
            if legend.get_window_extent(renderer).overlaps(ax.get_window_extent(renderer)):
                out.append(ax.get_title() or ax.get_ylabel())
    return out


@pytest.fixture
def laid_out(monkeypatch):
    """Every figure saved while the test runs: its problems recorded (``figures``: one dict each)."""
    figures = []

    def check(fig):
        if len(figures) >= 3:  # smooth draws a figure per pass: three tell as much as fourteen
            return
        figures.append({"clipped": clipped_texts(fig), "legends_inside": legends_inside_axes(fig, drawn=True),
                        "size_in": tuple(fig.get_size_inches()), "fig": fig,
                        "lines": {line.get_label(): line for ax in fig.axes for line in ax.get_lines()}})

    monkeypatch.setattr(plots, "FIGURE_CHECKS", [check])
    return figures


def png_size(data: bytes) -> tuple:
    """(width, height) in pixels from a PNG's IHDR chunk."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def assert_report_ready(figures, data: bytes, *, min_px=(700, 400), max_px=(2600, 4000)):
    """One figure or more saved, none with clipped text or a legend over the data, and an image
    between ``min_px`` and ``max_px``."""
    assert figures, "no figure went through plots.encode"
    for fig in figures:
        assert fig["clipped"] == [], fig["clipped"]
        assert fig["legends_inside"] == [], fig["legends_inside"]
    width, height = png_size(data)
    assert min_px[0] <= width <= max_px[0] and min_px[1] <= height <= max_px[1], (width, height)


def _frame():
    rng = np.random.default_rng(1)
    t = pd.date_range("2026-03-20T09:30:00Z", periods=200, freq="10s")
    rows = []
    for kind, sigma in (("range", 5.0), ("elevation", np.radians(0.01))):
        for i, time in enumerate(t):
            rows.append({"time": time, "station": "ZHY" if i < 100 else "KIR",
                         "pass_id": "ZHY-001" if i < 100 else "KIR-001", "kind": kind,
                         "residual": rng.normal(0, sigma), "edited": i == 7})
    return pd.DataFrame(rows)


def test_rms_per_pass_in_display_units():
    frame = _frame()
    rms = rms_by_pass(frame)
    el = frame[(frame["kind"] == "elevation") & (frame["pass_id"] == "ZHY-001") & ~frame["edited"]]
    assert rms[("elevation", "ZHY-001")][0] == pytest.approx(np.degrees(np.sqrt(np.mean(el["residual"] ** 2))))
    assert rms[("elevation", "ZHY-001")][1] == 99          # the edited sample left out
    assert 0.007 < rms[("elevation", "KIR-001")][0] < 0.013   # degrees, not radians
    assert 4.0 < rms[("range", "KIR-001")][0] < 6.0


def test_png_is_written(laid_out):
    png = residuals_png(_frame())
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert_report_ready(laid_out, png)


def test_the_check_sees_a_clipped_title_and_a_legend_over_the_data():
    """The layout checks can fail: a title wider than its figure and a legend in the axes."""
    plt = plots.pyplot()
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1], [0, 1], label="data")
    ax.legend(loc="upper left")
    fig.suptitle("a title much too long for a figure three inches wide, clipped at both edges")
    assert "a title much too long for a figure three inches wide, clippe" in [name for name, _ in clipped_texts(fig)]
    assert legends_inside_axes(fig) == [""]
    plt.close(fig)


def test_lines_break_at_gaps_only():
    t = np.r_[np.arange(0.0, 50.0, 5.0), np.arange(120.0, 150.0, 5.0)]   # a 75 s gap in a 5 s series
    y = t * 2
    tb, yb = break_gaps(t, y)
    assert np.isnan(tb).sum() == 1 and np.isnan(tb[10]) and tb[9] == 45.0 and tb[11] == 120.0
    assert np.array_equal(yb[~np.isnan(yb)], y)
    even = np.arange(0.0, 100.0, 5.0)
    assert np.array_equal(break_gaps(even, even)[0], even)      # no gap: unchanged
    jitter = even + np.r_[0, 1.5, -1.5] .repeat(7)[:20]
    assert not np.isnan(break_gaps(jitter)[0]).any()            # uneven steps are not gaps


def test_refine_figure_from_a_refinement(tmp_path, laid_out):
    """``refine --plot`` on the shipped pass with 70 s of it cut out: the figure is written beside
    the state file, nothing clipped, and the model line breaks at the gap (one NaN) instead of
    bridging it."""
    from trackproc.cli.app import main

    lines = (SAMPLE / "doppler_pass.csv").read_text().splitlines()
    raw = tmp_path / "gap.csv"
    raw.write_text("\n".join(lines[:301] + lines[371:]) + "\n")          # 1 s samples: 70 s missing
    passfile = tmp_path / "p.parquet"
    assert main(["-q", "ingest", str(raw), "--stations", str(SAMPLE / "stations.csv"),
                 "--carrier-hz", "2.2e9", "--mode", "one-way", "-o", str(passfile)]) == 0
    assert main(["-q", "refine", str(passfile), "--initial", str(SAMPLE / "stale.json"), "--doppler-bias",
                 "offset+drift", "--plot", str(tmp_path / "r.png"), "-o", str(tmp_path / "r.json")]) == 0
    assert (tmp_path / "r.json").exists()
    assert_report_ready(laid_out, (tmp_path / "r.png").read_bytes())
    model = laid_out[0]["lines"]["refined orbit (model)"]
    x = np.asarray(model.get_xdata(), float)
    assert np.isnan(x).sum() == 1
    k = int(np.flatnonzero(np.isnan(x))[0])
    assert x[k + 1] - x[k - 1] == pytest.approx(71.0)


def test_detect_figure(tmp_path, laid_out):
    from trackproc.cli.app import main

    sample = Path(__file__).resolve().parents[2] / "sample_data"
    passfile = tmp_path / "b.parquet"
    assert main(["-q", "simulate", "--ballistic", str(sample / "nominal.json"), "--stations",
                 str(sample / "stations.csv"), "--hypothesis", "h1", "--step", "2", "--elevation-mask-deg", "0",
                 "--seed", "1", "-o", str(passfile)]) == 0
    assert main(["-q", "detect", str(passfile), "--nominal", str(sample / "nominal.json"), "--plot",
                 str(tmp_path / "d.png"), "-o", str(tmp_path / "d.json")]) == 0
    assert_report_ready(laid_out, (tmp_path / "d.png").read_bytes())
    statistic_axes = laid_out[0]["fig"].axes[-1]
    assert statistic_axes.get_ylabel() == "probability density [1/rad^2]"


def test_smooth_figures_one_per_pass_png_and_pdf(tmp_path, laid_out):
    from trackproc.cli.app import main

    sample = Path(__file__).resolve().parents[2] / "sample_data"
    assert main(["-q", "smooth", str(sample / "multistation.parquet"), "--kinds", "elevation", "--plot",
                 str(tmp_path / "s.png"), "-o", str(tmp_path / "s.parquet")]) == 0
    pngs = sorted(p.name for p in tmp_path.glob("s-*.png"))
    assert len(pngs) == 14 and all(p.endswith("-elevation.png") for p in pngs)   # 14 passes, one figure each
    assert_report_ready(laid_out, (tmp_path / pngs[0]).read_bytes(), min_px=(1000, 300))   # a wide strip
    # the PDF: one page per pass in one file, on two of those passes (each page costs as much as a PNG)
    from trackproc.io.passfile import read_pass_table, write_pass_table
    from trackproc.types.passes import PassTable

    table = read_pass_table(str(sample / "multistation.parquet"))
    frame = table.frame
    two = sorted(frame.loc[frame["kind"] == "elevation", "pass_id"].unique())[:2]
    write_pass_table(PassTable(frame[frame["pass_id"].isin(two)].reset_index(drop=True), table.meta),
                     str(tmp_path / "two.parquet"))
    assert main(["-q", "smooth", str(tmp_path / "two.parquet"), "--kinds", "elevation", "--plot",
                 str(tmp_path / "s.pdf"), "-o", str(tmp_path / "s2.parquet")]) == 0
    pdf = (tmp_path / "s.pdf").read_bytes()
    assert pdf[:4] == b"%PDF" and pdf.count(b"/Type /Page\n") + pdf.count(b"/Type /Page ") + pdf.count(b"/Type/Page") == 2


def test_compare_figure_is_report_sized_with_the_raw_series_in_its_legend(tmp_path, laid_out):
    from trackproc.cli.app import main

    passfile = tmp_path / "p.parquet"
    assert main(["-q", "ingest", str(SAMPLE / "doppler_pass.csv"), "--stations", str(SAMPLE / "stations.csv"),
                 "--carrier-hz", "2.2e9", "--mode", "one-way", "-o", str(passfile)]) == 0
    assert main(["-q", "compare", str(passfile), str(SAMPLE / "truth.json"), "--plot", str(tmp_path / "c.png"),
                 "-o", str(tmp_path / "c.csv")]) == 0
    data = (tmp_path / "c.png").read_bytes()
    assert_report_ready(laid_out, data)
    assert png_size(data)[0] >= 800 and png_size(data)[1] >= 450     # 8 x 4.5 in at 100 dpi at least
    labels = [t.get_text() for legend in laid_out[0]["fig"].legends for t in legend.get_texts()]
    assert any(label.startswith("observed - predicted (raw") for label in labels)
    assert any(label.startswith("after removing") for label in labels)


def test_requirements_figure_in_degrees(tmp_path, laid_out):
    from trackproc.report.requirements_plots import plot_bytes

    data = plot_bytes(None, sigma_max_rad=0.01)
    assert_report_ready(laid_out, data)
    ax = laid_out[0]["fig"].axes[0]
    assert "[deg]" in ax.get_xlabel()
    assert ax.get_xlim()[1] == pytest.approx(np.degrees(0.01))
    # seed 003 Fig. 3's curve 1: dt = (g / sigma)^2 with sigma in radians, plotted against degrees
    line = ax.get_lines()[0]
    x, y = np.asarray(line.get_xdata()), np.asarray(line.get_ydata())
    from trackproc.pipeline.requirements import FIG3_G

    assert np.allclose(y, (FIG3_G[0] / np.radians(x)) ** 2)


def test_accuracy_figure_and_the_aliasing_warning(tmp_path, laid_out, run_cli):
    """An hourly step on a ~100 min orbit aliases it: a warning with a step that does not; a
    10-minute step draws without one."""
    png = tmp_path / "a.png"
    res = run_cli(["accuracy", SAMPLE / "truth.json", "--span", "6h", "--step", "1h", "--method", "stm",
                   "--sigma-position-m", "100", "--sigma-velocity-m-s", "0.1", "--plot", png, "-o", tmp_path / "a.csv"])
    assert res.exit_code == 0, res.stderr
    warning = [line for line in res.stderr.splitlines() if "alias" in line]
    assert len(warning) == 1 and "quarter of the orbital period" in warning[0] and "--step" in warning[0]
    import re

    suggested = int(re.search(r"--step (\d+)s", warning[0]).group(1))
    period = float(re.search(r"orbital period \((\d+) s\)", warning[0]).group(1))
    assert 4000 < period < 7000 and suggested == int(period / 20)
    res = run_cli(["accuracy", SAMPLE / "truth.json", "--span", "6h", "--step", "10m", "--method", "stm",
                   "--sigma-position-m", "100", "--sigma-velocity-m-s", "0.1", "--plot", png, "-o", tmp_path / "a.csv"])
    assert res.exit_code == 0 and "alias" not in res.stderr
    assert_report_ready(laid_out, png.read_bytes())


def test_filter_figure_bands_and_sigmas(tmp_path, laid_out):
    """``filter --plot`` on the shipped three-station set: a panel per kind whose ±3σ band is three
    times the innovation sigma of ``--residuals`` (its √S), angles in degrees, and a sigma panel
    whose last filtered R/T/N points are the state file's ``sigma_rtn`` (the filtered state at the
    last measurement)."""
    import json

    from trackproc.cli.app import main

    out, res, png = tmp_path / "f.json", tmp_path / "r.csv", tmp_path / "f.png"
    assert main(["-q", "filter", str(SAMPLE / "multistation.parquet"), "--initial", str(SAMPLE / "stale.json"),
                 "--range-bias", "--apriori-sigma", "range_bias=1000", "--kinds", "range,elevation",
                 "--residuals", str(res), "--plot", str(png), "-o", str(out)]) == 0
    assert_report_ready(laid_out, png.read_bytes())
    fig = laid_out[0]["fig"]
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == ["range innovation [m]", "elevation innovation [deg]", "position 1σ [m]"]
    table = pd.read_csv(res)
    for ax, kind, factor in ((fig.axes[0], "range", 1.0), (fig.axes[1], "elevation", np.degrees(1.0))):
        band = [line for line in ax.get_lines() if line.get_label() == "±3σ (3 √S)"][0]
        y = np.asarray(band.get_ydata(), float)
        expected = 3.0 * table.loc[table["kind"] == kind, "innovation_sigma"].to_numpy() * factor
        np.testing.assert_allclose(y[~np.isnan(y)], expected, rtol=1e-12)
    state = json.loads(out.read_text())
    lines = {line.get_label(): np.asarray(line.get_ydata(), float) for line in fig.axes[2].get_lines()}
    for key, name in (("radial_m", "R"), ("along_m", "T"), ("cross_m", "N")):
        assert lines[f"{name} (filtered)"][-1] == pytest.approx(state["diagnostics"]["sigma_rtn"][key], rel=1e-9)
    # the data shrank the position sigma from its first step to its last
    assert lines["T (filtered)"][-1] < 0.1 * lines["T (filtered)"][0]
