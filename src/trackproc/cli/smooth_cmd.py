"""``trackproc smooth``: least-squares polynomial smoothing of passes, TCA and carrier estimates."""

from __future__ import annotations

import logging
from enum import Enum
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.common import OutputOpt, TableFormat, resolve_output, table_format_for

log = logging.getLogger("trackproc")

KIND_NAMES = ("range_rate", "range", "doppler", "elevation", "azimuth")


class Basis(str, Enum):
    chebyshev = "chebyshev"
    legendre = "legendre"


def _degree(text: str):
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        raise typer.BadParameter(f"expected an integer >= 0 or auto, got {text!r}") from None
    if value < 0:
        raise typer.BadParameter(f"expected an integer >= 0 or auto, got {value}")
    return value


@app.command("smooth")
def smooth_command(
    input: str = typer.Argument(..., metavar="PASS", help="Canonical pass file (Parquet, Arrow, CSV), or - for stdin."),
    degree: str = typer.Option("auto", "--degree", metavar="N|auto",
                               help="Polynomial degree, or auto: minimum BIC over 0..--max-degree."),
    max_degree: int = typer.Option(30, "--max-degree", metavar="N", min=0, help="Largest degree --degree auto tries."),
    basis: Basis = typer.Option(Basis.chebyshev, "--basis", help="Basis on the pass interval mapped to [-1, 1]."),
    clip: float = typer.Option(4.0, "--clip", metavar="K",
                               help="Reject samples beyond K robust sigmas (iterated; flagged, not dropped). 0: off."),
    kinds: Optional[List[str]] = typer.Option(
        None, "--kinds", metavar="KIND[,KIND]",
        help="Kinds to fit (range_rate, range, doppler, elevation, azimuth); default: all present."),
    grid: Optional[str] = typer.Option(
        None, "--grid", metavar="STEP",
        help="Write the fitted curve every STEP seconds (or 0.5s, 1m; value = curve, sigma = its 1-sigma) "
             "instead of the samples."),
    tca_max_gap: str = typer.Option(
        "30", "--tca-max-gap", metavar="S",
        help="A TCA inside a data gap longer than S s, or within S s of either end of the data, is 'not observed'."),
    summary: Optional[str] = typer.Option(None, "--summary", metavar="SUMMARY.json",
                                          help="JSON summary per pass and kind (- for stdout when -o is a file)."),
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png|FILE.pdf",
                                       help="Plot data, fit and residuals, one figure per pass and kind: a PDF "
                                            "of one page each, or FILE-<pass>-<kind>.png files (needs matplotlib: "
                                            "pip install 'trackproc[plot]')."),
    fmt: Optional[TableFormat] = typer.Option(
        None, "--format", help="Output format (default: from the suffix; Arrow stream on stdout)."),
    output: Optional[str] = OutputOpt,
) -> None:
    """Fit each pass (station, pass_id, kind) by weighted least squares with a generalized polynomial
    (seed 004 eq. 1) and add the columns smoothed, residual and flag (true = not used by the fit).

    For range-rate and Doppler passes the summary gives the time of closest approach with its
    standard error, and for one-way Doppler the carrier at closest approach (fca_hz).

    Exit status: 0 when at least one pass was fitted (failed passes are reported on stderr and in
    the summary with status "failed"); 1 when none could be fitted; 2 for invalid input or options.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc smooth sample_data/multistation.parquet --summary smooth.json -o smooth.parquet

        trackproc ingest sample_data/doppler_pass.csv --stations sample_data/stations.csv \\
            --carrier-hz 2.2e9 --mode one-way | trackproc smooth - --grid 1 > curve.parquet
    """
    from trackproc.io.validate import parse_duration

    grid = None if grid is None else parse_duration(grid, "--grid")
    tca_max_gap = parse_duration(tca_max_gap, "--tca-max-gap")
    degree_value = _degree(degree)
    kind_list = [k.strip() for item in (kinds or []) for k in item.split(",") if k.strip()]
    bad = [k for k in kind_list if k not in KIND_NAMES]
    if bad:
        raise typer.BadParameter(f"unknown kind {', '.join(bad)}; expected {', '.join(KIND_NAMES)}",
                                 param_hint="--kinds")
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    out = resolve_output(output, "output pass file")
    if summary == "-" and out == "-":
        raise typer.BadParameter("stdout already carries the table; give --summary a file, or -o a file",
                                 param_hint="--summary")
    out_format = table_format_for(out, fmt)

    from trackproc.io.atomic import is_stdio, write_bytes, write_text
    from trackproc.io.passfile import read_pass_table, write_pass_table
    from trackproc.pipeline.smooth import SmoothOptions, require_matplotlib, smooth, summary_json

    if plot is not None:
        require_matplotlib()
    table = read_pass_table(input)
    if grid is not None:
        _check_grid_rows(table, grid)
    options = SmoothOptions(degree=degree_value, clip=clip if clip > 0 else None, kinds=kind_list or None,
                            basis=basis.value, max_degree=max_degree, grid_step_s=grid, tca_max_gap_s=tca_max_gap)
    result = smooth(table, options, source="<stdin>" if is_stdio(input) else input)

    for f in result.fits:
        if f.status == "failed":
            log.warning("%s: failed: %s", f.label, f.error)
        elif f.status == "suspect":
            detail = f"; {f.tca_error}" if f.tca_error else ""
            log.warning("%s: suspect (%s)%s", f.label, ", ".join(f.warnings), detail)
    if plot is not None:
        from trackproc.report.plots import smooth_plots

        figures = smooth_plots(result, plot)
    write_pass_table(result.table, out, out_format.value)
    if summary is not None:
        write_text(summary, summary_json(result.summary, ready=True))
    if plot is not None:
        for name, data in figures.items():
            write_bytes(name, data)
        log.info("plot: %s", ", ".join(figures))
    counts = result.summary["counts"]
    log.info("%d fits: %d ok, %d suspect, %d failed -> %s (%s)", counts["fits"], counts["ok"], counts["suspect"],
             counts["failed"], "stdout" if out == "-" else out, out_format.value)


def _check_grid_rows(table, grid) -> None:
    """``--grid`` rows over every pass and kind, bounded before anything is computed (a grid of
    1e-7 s would exhaust the memory)."""
    import math

    from trackproc.io.validate import check_rows

    if not (isinstance(grid, (int, float)) and math.isfinite(grid) and grid > 0):
        return   # smooth's own option check names it
    frame = table.frame
    if frame.empty:
        return
    spans = frame.groupby(["station", "pass_id", "kind"])["time"].agg(["min", "max"])
    seconds = (spans["max"] - spans["min"]).dt.total_seconds()
    check_rows(float((seconds / grid + 1).sum()), "grid rows", column="--grid")

