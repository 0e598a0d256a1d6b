"""``trackproc compare``: residuals of a pass against a prediction (state or TLE)."""

from __future__ import annotations

import logging
from enum import Enum
from typing import Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.common import Dut1Opt, EarthOpt, EopOpt, RangeRateModelOpt
from trackproc.cli.force_options import ForceSettings, force_options, full_force_model
from trackproc.cli.propagate_cmd import OrbitForce, OrbitForceOpt

log = logging.getLogger("trackproc")


class Remove(str, Enum):
    none = "none"
    offset = "offset"
    offset_drift = "offset+drift"


@app.command("compare")
@force_options
def compare_command(
    pass_file: str = typer.Argument(..., metavar="PASS", help="Pass file (Parquet, Arrow, CSV); - for stdin."),
    prediction: str = typer.Argument(..., metavar="STATE.json|TLE|metadata",
                                     help="The prediction: a state file, a TLE, or 'metadata' for the TLE stored in "
                                          "the pass file (DopTrack)."),
    remove: Remove = typer.Option(Remove.offset_drift, "--remove",
                                  help="Fitted per pass and kind and removed before the RMS: none, offset, "
                                       "offset+drift (a transmitter's frequency error)."),
    stations: Optional[str] = typer.Option(None, "--stations", metavar="STATIONS.csv",
                                           help="Stations table (default: the pass file's stations)."),
    force: Optional[OrbitForce] = OrbitForceOpt,
    earth=EarthOpt,
    range_rate_model=RangeRateModelOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    summary_path: Optional[str] = typer.Option(None, "--summary", metavar="FILE",
                                               help="Also write the JSON summary here (it always goes to stderr)."),
    output: Optional[str] = typer.Option(None, "-o", "--output",
                                         help="Residuals per sample (Parquet, Arrow on -, CSV by suffix)."),
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png",
                                       help="Plot the residuals per pass and kind, before and after the removal "
                                            "(needs matplotlib: trackproc[plot])."),
    force_settings: ForceSettings = None,
) -> None:
    """Compare a pass with a prediction: residuals observed - predicted per sample (-o), and per
    pass and kind the RMS after removing the pass's own fitted offset (and drift), with those
    fitted values (JSON on stderr and --summary). A TLE is evaluated by SGP4 at the samples.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc ingest sample_data/doppler_pass.csv --stations sample_data/stations.csv \\
            --carrier-hz 2.2e9 --mode one-way -o pass.parquet
        trackproc compare pass.parquet sample_data/truth.json --summary fit.json -o residuals.csv

        trackproc compare sample_data/multistation.parquet sample_data/stale.json --remove none

    Exit status: 0 ok; 2 bad options or input; 1 propagation failure.
    """
    import json
    import sys

    from trackproc.io.atomic import write_text
    from trackproc.io.eop import earth_orientation
    from trackproc.io.passfile import read_pass_table
    from trackproc.io.residuals import format_for, write_residuals
    from trackproc.io.stations import read_stations
    from trackproc.io.jsonutil import json_ready
    from trackproc.pipeline.compare import CompareOptions, compare
    from trackproc.pipeline.orbit_source import read_orbit

    if pass_file == "-" and prediction == "-":
        raise typer.BadParameter("only one input can come from stdin", param_hint="PREDICTION")
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    if plot is not None:
        from trackproc.pipeline.plotting import require_matplotlib

        require_matplotlib()
    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    table = read_pass_table(pass_file)
    if prediction == "metadata":
        from trackproc.pipeline.orbit_source import OrbitInput, tle_from_pass_metadata

        source = "<stdin>" if pass_file == "-" else pass_file
        tle = tle_from_pass_metadata(table, source)
        orbit = OrbitInput(tle=tle, source=tle.source)
    else:
        orbit = read_orbit(prediction, orientation)
    extra = read_stations(stations) if stations is not None else None
    options = CompareOptions(remove=remove.value, force=force.value if force is not None else None,
                             earth=earth.value, range_rate_model=range_rate_model.value)
    options.force_model = full_force_model(force_settings, orbit, force, orientation)
    residuals, summary = compare(table, orbit, options, orientation, extra)
    text = json.dumps(json_ready(summary), indent=2) + "\n"
    if plot is not None:
        from trackproc.io.atomic import write_bytes
        from trackproc.report.compare_plots import plot_bytes

        write_bytes(plot, plot_bytes(residuals, summary))
    if output is not None:
        write_residuals(residuals, output, {k: v for k, v in summary.items() if k != "passes"}, format_for(output))
    if summary_path is not None:
        write_text(summary_path, text)
    if "note" in summary:
        log.info("%s", summary["note"])
    sys.stderr.write(text)
    for p in summary["passes"]:
        log.info("%s %s: %d samples, RMS %.4g %s after removing %s (raw %.4g)", p["pass_id"], p["kind"], p["samples"],
                 p["rms"], p["unit"], options.remove, p["rms_raw"])


__all__ = ["compare_command"]
