"""``trackproc fit-tle``: SGP4 mean elements (a new TLE) fitted to passes and/or ephemerides."""

from __future__ import annotations

import logging
import math
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.common import (Dut1Opt, EarthOpt, EopOpt, JsonSummaryOpt, RangeRateModelOpt, StrictOpt,
                                  resolve_output)

log = logging.getLogger("trackproc")


@app.command("fit-tle")
def fit_tle_command(
    passes: List[str] = typer.Argument(None, metavar="PASS...",
                                       help="Pass files (Parquet, Arrow, CSV from ingest/simulate); - for stdin."),
    initial: str = typer.Option(..., "--initial", metavar="TLE|STATE.json|metadata",
                                help="The initial orbit and a-priori: a TLE (its catalogue number, designator and "
                                     "name are kept), a state file, or 'metadata' for the TLE stored in the pass "
                                     "files (DopTrack; the newest)."),
    ephemeris: List[str] = typer.Option([], "--ephemeris", metavar="EPHEMERIS",
                                        help="Also fit to the positions of an ephemeris (Parquet, Arrow, CSV from "
                                             "propagate; its sigma_x_m.. columns, else --ephemeris-sigma); repeatable."),
    epoch: Optional[str] = typer.Option(None, "--epoch", metavar="ISO",
                                        help="Epoch of the new TLE (default: the middle of the last pass)."),
    fix_bstar: bool = typer.Option(False, "--fix-bstar", help="Keep the initial B* instead of fitting it."),
    doppler_bias: str = typer.Option("offset+drift", "--doppler-bias", metavar="none|offset|offset+drift",
                                     help="Fitted per pass and kind of one-way Doppler and range-rate (the "
                                          "transmitter's frequency error)."),
    kinds: Optional[str] = typer.Option(None, "--kinds", metavar="KIND[,KIND]",
                                        help="Kinds to use: doppler, range_rate, range, azimuth, elevation (default all)."),
    stations: Optional[str] = typer.Option(None, "--stations", metavar="STATIONS.csv",
                                           help="Stations table (default: the pass files' stations)."),
    satnum: Optional[str] = typer.Option(None, "--satnum", metavar="NUMBER",
                                         help="Catalogue number of the new TLE (default: the initial TLE's; 99999 "
                                              "for a state)."),
    ephemeris_sigma: float = typer.Option(100.0, "--ephemeris-sigma", metavar="M", min=0.0,
                                          help="1-sigma (m) of ephemeris positions without sigma columns."),
    clip: float = typer.Option(4.0, "--clip", metavar="K", min=0.0,
                               help="Edit samples beyond K x max(1, RMS) sigmas of their pass and kind. 0: off."),
    apriori: bool = typer.Option(True, "--apriori/--no-apriori",
                                 help="Constrain the elements by the initial orbit (--apriori-model, its along-track "
                                      "error grown with the age of the initial TLE)."),
    apriori_model: str = typer.Option("tle", "--apriori-model", metavar="tle|refine",
                                      help="The initial TLE's a-priori: 'tle' its measured accuracy (TLE "
                                           "differencing: 200 m along-track at its epoch growing 550 m/day, radial "
                                           "100 m, cross-track 50 m; docs/fit-tle.md) or 'refine' refine's default "
                                           "element sigmas (~10x looser; always for a state and a TLE over 3.2 "
                                           "days from the epoch)."),
    horizon: str = typer.Option("1", "--horizon", metavar="DAYS",
                                help="How far after the epoch the TLE must predict better than the initial one, "
                                     "days, or with a unit: 12h, 2d (the refusal test and the summary's prediction)."),
    max_iterations: int = typer.Option(30, "--max-iterations", min=1, help="Iterations at most."),
    cross_validate: bool = typer.Option(False, "--cross-validate",
                                        help="Also leave each pass file out in turn, fit the others and predict it: "
                                             "the fitted TLE's prediction skill against the initial orbit's (one "
                                             "extra fit per file; 'suspect' when worse in the median)."),
    model_error: Optional[float] = typer.Option(None, "--model-error", metavar="SCALE", min=0.0,
                                                help="SGP4's own theory error at each pass, in units of the default "
                                                     "a-priori's element sigmas (independent per pass; default 3.4, "
                                                     "calibrated on DopTrack Delfi-C3 passes, docs/fit-tle.md). 0: "
                                                     "none (the covariance then covers the estimation error only)."),
    refusal: bool = typer.Option(True, "--refusal/--no-refusal",
                                 help="Keep the initial TLE (written unchanged, verdict suspect 'refused') when the "
                                      "fit cannot be shown to predict better: one pass, or a fit that predicts the "
                                      "position --horizon days on better with probability below 0.9. --no-refusal "
                                      "writes the fit."),
    earth=EarthOpt,
    range_rate_model=RangeRateModelOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    summary_path: Optional[str] = typer.Option(None, "--summary", metavar="FILE",
                                               help="Also write the JSON summary (elements, covariance, verdict) here."),
    residuals: Optional[str] = typer.Option(None, "--residuals", metavar="FILE",
                                            help="Write the residuals of the fit (Parquet, or CSV by the .csv "
                                                 "suffix; estimate's columns)."),
    as_json: bool = JsonSummaryOpt,
    strict: bool = StrictOpt,
    output: str = typer.Option("-", "-o", "--output", help="The new TLE (default: stdout)."),
) -> None:
    """Fit a TLE (SGP4 mean elements and B*) to Doppler, range-rate, range or angle passes and/or to
    ephemeris positions by least squares, starting from and constrained by an initial TLE or
    state, with each one-way pass's transmitter offset and drift fitted. Writes a valid TLE
    (checksums; catalogue number, classification, designator and name kept; epoch the middle of
    the last pass unless --epoch) and a summary with the elements' covariance and a quality
    verdict (ok, suspect, rejected) on stderr.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc simulate --tle sample_data/iss.tle --stations sample_data/stations.csv --duration 21600 \\
            --kinds doppler --carrier-hz 145.8e6 -o iss.parquet
        trackproc fit-tle iss.parquet --initial sample_data/iss.tle -o fitted.tle --summary fit.json

    Exit status: 0 ok; 1 the fit failed or its verdict is 'rejected' (or 'suspect' with --strict;
    the TLE is written); 2 bad options or input.

    \f
    Over 100 lines because it declares the options (each with its help); the work is in
    pipeline/fit_tle/ (run), with the reading and writing around it here.
    """
    from trackproc.io.validate import parse_duration

    horizon = parse_duration(horizon, "--horizon", plain_unit_s=86400.0) / 86400.0
    import json
    import sys

    import numpy as np

    from trackproc.io.atomic import is_stdio, write_text
    from trackproc.io.eop import earth_orientation
    from trackproc.io.ephemeris import read_ephemeris
    from trackproc.io.jsonutil import json_ready
    from trackproc.io.passfile import read_pass_table
    from trackproc.io.stations import read_stations
    from trackproc.io.tle import tle_text
    from trackproc.pipeline.fit_tle import DOPPLER_BIAS, FitTleOptions, fit_tle
    from trackproc.report.fit_tle_text import summary_text
    from trackproc.pipeline.orbit_source import initial_orbit

    passes = list(passes or [])
    output = resolve_output(output, "TLE output")
    if doppler_bias not in DOPPLER_BIAS:
        raise typer.BadParameter(f"{doppler_bias!r} is not one of {', '.join(DOPPLER_BIAS)}",
                                 param_hint="--doppler-bias")
    if apriori_model not in ("tle", "refine"):
        raise typer.BadParameter(f"{apriori_model!r} is not one of tle, refine", param_hint="--apriori-model")
    if not (horizon > 0 and math.isfinite(horizon)):
        raise typer.BadParameter(f"{horizon:g} is not a positive, finite number of days", param_hint="--horizon")
    if not passes and not ephemeris:
        raise typer.BadParameter("give pass files and/or --ephemeris files to fit", param_hint="PASS")
    stdin_users = [p for p in passes + list(ephemeris) if is_stdio(p)] + ([initial] if is_stdio(initial) else [])
    if residuals == "-" and output == "-":
        raise typer.BadParameter("stdout already carries the TLE; give --residuals a file", param_hint="--residuals")
    if len(stdin_users) > 1:
        raise typer.BadParameter("only one input can come from stdin", param_hint="PASS")
    if len(set(passes)) != len(passes):
        raise typer.BadParameter("a pass file is given twice", param_hint="PASS")
    at = None
    if epoch is not None:
        from trackproc.io.statefile import parse_epoch

        at = parse_epoch(epoch, column="--epoch")
    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    tables = [("<stdin>" if is_stdio(p) else p, read_pass_table(p)) for p in passes]
    ephemerides = [("<stdin>" if is_stdio(e) else e, read_ephemeris(e)) for e in ephemeris]
    orbit = initial_orbit(initial, tables, orientation)
    if orbit.tle is not None and initial == "metadata":
        log.info("initial orbit: %s", orbit.source)
    extra = read_stations(stations) if stations is not None else None
    options = FitTleOptions(
        epoch=np.datetime64(at, "ns") if at is not None else None, fit_bstar=not fix_bstar, doppler_bias=doppler_bias,
        kinds=[k.strip() for k in kinds.split(",") if k.strip()] if kinds else None, earth=earth.value,
        range_rate_model=range_rate_model.value, ephemeris_sigma_m=ephemeris_sigma if ephemeris_sigma > 0 else 100.0,
        clip=clip if clip > 0 else float("inf"), max_iterations=max_iterations, satnum=satnum, apriori=apriori,
        cross_validate=cross_validate, model_error=model_error, refusal=refusal, apriori_model=apriori_model,
        prediction_span_days=horizon)
    result = fit_tle(tables, ephemerides, orbit, options, orientation, extra)
    text = json.dumps(json_ready(result.summary), indent=2) + "\n"
    write_text(output, tle_text(result.tle))
    if summary_path is not None:
        write_text(summary_path, text)
    if residuals is not None:
        from trackproc.io.residuals import write_residuals

        write_residuals(result.residuals, residuals, {"command": "fit-tle", "epoch": result.summary["epoch"],
                                                      "tle": result.summary["tle"], "parameters": list(
                                                          result.summary["elements"]),
                                                      "sources": sorted({str(s) for s, _ in tables + ephemerides})})
    if log.isEnabledFor(logging.WARNING):
        sys.stderr.write(text if as_json else summary_text(result))
        sys.stderr.flush()
    verdict = result.quality.verdict
    if verdict == "rejected" or (strict and verdict == "suspect"):
        log.error(f"{result.quality.text()}: the TLE is written with its verdict in the summary; exit 1"
                  + (" (--strict)" if verdict == "suspect" else ""))
        from trackproc.io.atomic import commit_outputs

        commit_outputs()
        raise typer.Exit(1)


__all__ = ["fit_tle_command"]
