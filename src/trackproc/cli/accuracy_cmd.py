"""``trackproc accuracy``: sigma(t) of a predicted orbit from its initial covariance (seed 000)."""

from __future__ import annotations

import logging
from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.force_options import ForceSettings, force_options
from trackproc.cli.common import (Dut1Opt, EarthOpt, EopOpt, ForceOpt, JsonSummaryOpt, OutputOpt, resolve_output,
                                  table_format_for)

log = logging.getLogger("trackproc")


class Method(str, Enum):
    spectral = "spectral"
    stm = "stm"
    monte_carlo = "monte-carlo"
    all = "all"


class OutFormat(str, Enum):
    parquet = "parquet"
    arrow = "arrow"
    csv = "csv"
    json = "json"


class SigmaFrame(str, Enum):
    gcrf = "gcrf"
    rtn = "rtn"


def _numbers(text: Optional[str], flag: str, count=(1, 3)):
    if text is None:
        return None
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        values = []
    if len(values) not in count:
        want = " or ".join(str(c) for c in count)
        raise typer.BadParameter(f"expected {want} comma-separated number(s), got {text!r}", param_hint=flag)
    return values


def _format_for(path: str, requested: Optional[OutFormat]) -> str:
    if requested is not None:
        return requested.value
    if path != "-" and Path(path).suffix.lower() == ".json":
        return "json"
    return table_format_for(path, None).value


@app.command("accuracy")
@force_options
def accuracy_command(
    state: Optional[str] = typer.Argument(None, metavar="STATE.json",
                                          help="State file with covariance (e.g. from estimate), a TLE, or - "
                                               "for stdin. Not with --seed-example."),
    span: Optional[str] = typer.Option(None, "--span", metavar="S", help="Prediction span from the epoch, s, or with a unit: 90s, 45m, 6h, 2d."),
    step: Optional[str] = typer.Option(None, "--step", metavar="S", help="Output time step, s, or with a unit: 90s, 45m, 6h, 2d."),
    force=ForceOpt,
    method: Method = typer.Option(Method.spectral, "--method",
                                  help="spectral (seed 000 image domain), stm (Phi P0 Phi^T), monte-carlo, "
                                       "or all three side by side."),
    monte_carlo: Optional[int] = typer.Option(None, "--monte-carlo", metavar="N",
                                              help="Monte Carlo draws (default 1000 with --method monte-carlo|all; "
                                                   "with spectral or stm: adds mc_ columns)."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, max=2**63 - 1, help="Random seed of the Monte Carlo draws."),
    sigma_position_m: Optional[str] = typer.Option(
        None, "--sigma-position-m", metavar="S|SX,SY,SZ",
        help="Initial position sigma, m (one value, or three); with --sigma-velocity-m-s replaces the file's "
             "covariance."),
    sigma_velocity_m_s: Optional[str] = typer.Option(
        None, "--sigma-velocity-m-s", metavar="S|SX,SY,SZ", help="Initial velocity sigma, m/s (one value, or three)."),
    sigma_frame: SigmaFrame = typer.Option(SigmaFrame.gcrf, "--sigma-frame",
                                           help="Axes of the three sigmas: gcrf (x, y, z) or rtn (radial, along, "
                                                "cross)."),
    at_station: Optional[str] = typer.Option(None, "--at-station", metavar="ID",
                                             help="Also sigma of range and range-rate at this station."),
    stations: Optional[str] = typer.Option(None, "--stations", metavar="STATIONS.csv",
                                           help="Stations table (with --at-station)."),
    earth=EarthOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    correlation: Optional[str] = typer.Option(
        None, "--correlation", metavar="FILE",
        help="Also write R(t_i, t_j) of every component (.json: matrices; .csv/.parquet: one row per pair)."),
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png",
                                       help="sigma(t) curves (needs matplotlib: trackproc[plot])."),
    seed_example: bool = typer.Option(False, "--seed-example",
                                      help="Run seed 000's worked example instead (circular orbit, one axis): "
                                           "exact, enough discretes, and truncated at --discretes."),
    radius_m: float = typer.Option(7.0e6, "--radius-m", help="--seed-example: orbit radius, m."),
    discretes: str = typer.Option("4,6", "--discretes", metavar="N[,N]",
                                  help="--seed-example: truncations to compare (the paper: 4 and 6)."),
    fmt: Optional[OutFormat] = typer.Option(None, "--format",
                                            help="parquet, arrow, csv or json (default: from the suffix; "
                                                 "Arrow stream on a pipe)."),
    as_json: bool = JsonSummaryOpt,
    output: Optional[str] = OutputOpt,
    force_settings: ForceSettings = None,
) -> None:
    """Predict the accuracy of an orbit from its initial covariance: sigma(t) of position and
    velocity (GCRF and radial / along-track / cross-track), of range and range-rate at a station,
    and the correlation function R(t_i, t_j), by the differential spectrum of seed 000,
    cross-checked by Phi P0 Phi^T and Monte Carlo. One row per time; other methods as stm_ / mc_
    prefixed columns.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc accuracy sample_data/stale.json --span 86400 --step 600 --method all -o sigma.parquet

        trackproc accuracy --seed-example -o example.csv

    \f
    Over 100 lines because it declares the options (each with its help); the work is in
    pipeline/accuracy/ (run), with the reading and writing around it here.
    """
    from trackproc.io.validate import parse_duration

    span = None if span is None else parse_duration(span, "--span")
    step = None if step is None else parse_duration(step, "--step")
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    if seed_example:
        if state is not None:
            raise typer.BadParameter("--seed-example takes no STATE argument", param_hint="STATE.json")
        _seed_example(span, step, sigma_position_m, sigma_velocity_m_s, radius_m, discretes, plot, fmt, output)
        return
    if state is None:
        raise typer.BadParameter("missing STATE.json (or use --seed-example)", param_hint="STATE.json")
    for flag, value in (("--span", span), ("--step", step)):
        if value is None:
            raise typer.BadParameter(f"{flag} is required", param_hint=flag)
    if at_station is not None and stations is None:
        raise typer.BadParameter("--at-station needs --stations STATIONS.csv", param_hint="--stations")
    from trackproc.io.validate import check_span

    check_span(span, "prediction span", column="--span")   # decades of propagation would run for hours
    pos = _numbers(sigma_position_m, "--sigma-position-m")
    vel = _numbers(sigma_velocity_m_s, "--sigma-velocity-m-s")
    out = resolve_output(output, "output table")
    out_format = _format_for(out, fmt)
    if correlation is not None and correlation == "-" and out == "-":
        raise typer.BadParameter("stdout already carries the table; give --correlation a file", param_hint="--correlation")

    from trackproc.io.atomic import write_bytes
    from trackproc.io.eop import earth_orientation
    from trackproc.io.statefile import read_state_or_tle
    from trackproc.pipeline.accuracy import (
        AccuracyOptions,
        accuracy,
        correlation_bytes,
        require_matplotlib,
        table_bytes,
    )
    from trackproc.report.accuracy_plots import plot_bytes

    if plot is not None:
        require_matplotlib()
    orientation, warning = earth_orientation(eop, dut1)
    if warning and at_station is not None:
        log.warning(warning)
    initial = read_state_or_tle(state, orientation)
    table = None
    if stations is not None:
        from trackproc.io.stations import read_stations

        table = read_stations(stations)
    options = AccuracyOptions(span_s=span, step_s=step, force=force.value, method=method.value,
                              monte_carlo=monte_carlo, seed=seed, sigma_position_m=pos, sigma_velocity_m_s=vel,
                              sigma_frame=sigma_frame.value, at_station=at_station, earth=earth.value,
                              correlation=correlation is not None,
                              force_model=force_settings.model(force.value, initial.epoch, orientation, initial))
    result = accuracy(initial, options, table, orientation, stations_source=stations)

    from trackproc.cli.common import summary

    checks = result.meta["checks"]
    if as_json:
        import json

        from trackproc.io.jsonutil import json_ready

        summary(json.dumps(json_ready({"command": "accuracy", "initial_covariance": result.meta["initial_covariance"],
                                       "methods": result.meta["methods"], "checks": checks}), allow_nan=False))
    else:
        summary(f"initial covariance: {result.meta['initial_covariance']['source']}")
    if "spectral_vs_stm_max_relative_sigma_difference" in checks and not as_json:
        summary(f"spectral vs stm: largest relative sigma difference "
                f"{checks['spectral_vs_stm_max_relative_sigma_difference']:.2e}")
    if "monte_carlo_vs_linear_max_abs_z" in checks:
        z = checks["monte_carlo_vs_linear_max_abs_z"]
        sd = checks["monte_carlo_variance_relative_sd"]
        text = (f"monte carlo vs {checks['monte_carlo_vs_linear_reference']}: largest |z| {z:.2f} "
                f"(variance ratio - 1 in units of its sd sqrt(2/(N-1)) = {sd:.3%})")
        if z > 5:
            log.warning("%s: beyond the statistical bound, the first-order methods miss a nonlinearity "
                        "over this span", text)
        elif not as_json:
            summary(text)
    if plot is not None:
        _warn_aliasing(initial, result.frame["elapsed_s"].to_numpy())
    png = plot_bytes(result) if plot is not None else None
    write_bytes(out, table_bytes(result.frame, result.meta, out_format))
    if correlation is not None:
        write_bytes(correlation, correlation_bytes(result, _format_for(correlation, None)))
    if png is not None:
        write_bytes(plot, png)
    log.info("%d times, %s -> %s (%s)", len(result.frame), "+".join(result.meta["methods"]),
             "stdout" if out == "-" else out, out_format)


def _warn_aliasing(initial, elapsed_s) -> None:
    """Warn when the output step exceeds a quarter of the orbital period (semi-major axis by the
    vis-viva equation, period 2 pi sqrt(a^3/mu) by Kepler's third law; Vallado, Fundamentals of
    Astrodynamics and Applications, ch. 1-2): the plotted sigma then
    samples the once-per-revolution oscillation of the along-track error too coarsely to show it
    (it zigzags, aliased), so the figure would mislead; the table is right at its own times."""
    import numpy as np

    from trackproc.constants import MU_EARTH

    if len(elapsed_s) < 2:
        return
    r = float(np.linalg.norm(initial.r_m))
    v2 = float(np.dot(initial.v_m_s, initial.v_m_s))
    inverse_a = 2.0 / r - v2 / MU_EARTH
    if inverse_a <= 0:  # not a closed orbit: no period to alias
        return
    period = 2 * np.pi * np.sqrt((1.0 / inverse_a) ** 3 / MU_EARTH)
    step = float(np.median(np.diff(elapsed_s)))
    if step > period / 4:
        suggest = max(1, int(period / 20))
        log.warning("--plot: the step of %.0f s is more than a quarter of the orbital period (%.0f s): the curves "
                    "alias the orbit (the along-track sigma zigzags); give --step %ds or less for a smooth figure",
                    step, period, suggest)


def _seed_example(span, step, sigma_position_m, sigma_velocity_m_s, radius_m, discretes, plot, fmt, output):
    pos = _numbers(sigma_position_m, "--sigma-position-m", (1,))
    vel = _numbers(sigma_velocity_m_s, "--sigma-velocity-m-s", (1,))
    try:
        nds = tuple(int(x) for x in discretes.split(",") if x.strip())
    except ValueError:
        raise typer.BadParameter(f"expected integers such as 4,6, got {discretes!r}", param_hint="--discretes") from None
    out = resolve_output(output, "output table")
    out_format = _format_for(out, fmt)

    from trackproc.io.atomic import write_bytes
    from trackproc.pipeline.accuracy import (
        SeedExampleOptions,
        require_matplotlib,
        seed_example,
        table_bytes,
    )
    from trackproc.report.accuracy_plots import seed_example_plot_bytes

    if plot is not None:
        require_matplotlib()
    defaults = SeedExampleOptions()
    options = SeedExampleOptions(span_s=defaults.span_s if span is None else span,
                                 step_s=defaults.step_s if step is None else step, radius_m=radius_m,
                                 sigma_position_m=defaults.sigma_position_m if pos is None else pos[0],
                                 sigma_velocity_m_s=defaults.sigma_velocity_m_s if vel is None else vel[0],
                                 discretes=nds)
    result = seed_example(options)
    png = seed_example_plot_bytes(result) if plot is not None else None
    write_bytes(out, table_bytes(result.frame, result.meta, out_format))
    if png is not None:
        write_bytes(plot, png)
    log.info("seed 000 example: n = %.6e rad/s, %d times -> %s (%s)", result.n_rad_s, len(result.frame),
             "stdout" if out == "-" else out, out_format)
