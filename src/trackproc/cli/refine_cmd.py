"""``trackproc refine``: refine a stale orbit from one Doppler pass of one station (seed 004)."""

from __future__ import annotations

import logging
from enum import Enum
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc import vocabulary
from trackproc.cli.common import (Dut1Opt, EarthOpt, EopOpt, ForceOpt, HorizonOpt, JsonSummaryOpt, Noise,
                                  OpmObjectIdOpt, OpmObjectNameOpt, OscillatorNoiseOpt, OutputOpt, PassRangeRateModelOpt,
                                  RangeRateModel, StrictOpt, choices, named_values, resolve_output)

log = logging.getLogger("trackproc")


class Cost(str, Enum):
    pointwise = "pointwise"
    integral = "integral"


DopplerBias = choices("DopplerBias", vocabulary.REFINE_DOPPLER_BIASES)


class Kind(str, Enum):
    doppler = "doppler"
    range_rate = "range_rate"


class OutputEpoch(str, Enum):
    traverse = "traverse"
    stale = "stale"


class Covariance(str, Enum):
    profile = "profile"
    linear = "linear"



@app.command("refine")
def refine_command(
    input: str = typer.Argument(..., metavar="PASS",
                                help="One pass of one station (raw or smoothed; Parquet, Arrow, CSV), or - for stdin."),
    initial: str = typer.Option(..., "--initial", metavar="STATE.json|TLE|metadata",
                                help="The stale state: a state file (optional covariance) or a TLE (SGP4 at the "
                                     "traverse epoch); metadata = the TLE stored in the pass file (DopTrack)."),
    stations: Optional[str] = typer.Option(
        None, "--stations", metavar="STATIONS.csv",
        help="Stations table (station, lat_deg, lon_deg, height_m); default: the pass file's metadata."),
    cost: Cost = typer.Option(Cost.pointwise, "--cost",
                              help="pointwise: least squares on the samples with the stale state as a-priori "
                                   "(default); integral: seed 004 eq. 14 on the smoothed curve."),
    circular: bool = typer.Option(
        False, "--circular",
        help="Impose the circular-orbit constraints of seed 004 eq. 5 (Lagrange multipliers); a warning when the "
             "pass contradicts them (likelihood-ratio test)."),
    circular_tolerance: float = typer.Option(
        0.0, "--circular-tolerance", metavar="E", min=0.0,
        help="With --circular: the eccentricity to which the orbit is circular; the constraints then hold to "
             "that uncertainty and are estimated with the state (0: exact constraints, covariance conditional "
             "on an exactly circular orbit)."),
    doppler_bias: Optional[DopplerBias] = typer.Option(
        None, "--doppler-bias",
        help="Transmitter frequency offset (and drift) to estimate; default: offset for one-way Doppler, none "
             "for range-rate and two-way data."),
    apriori: Optional[bool] = typer.Option(
        None, "--apriori/--no-apriori",
        help="Use the stale state as an a-priori (its covariance, else the default of docs/refine.md). "
             "Default: on for pointwise, off for integral."),
    apriori_sigma: List[str] = typer.Option(
        [], "--apriori-sigma", metavar="NAME=SIGMA",
        help="A-priori 1-sigma (SI) of a parameter (x, vx, doppler_offset) or position/velocity/state; repeatable; "
             "overrides the stale covariance."),
    pass_id: Optional[str] = typer.Option(None, "--pass-id", metavar="ID",
                                          help="The pass, when the file holds several."),
    kind: Optional[Kind] = typer.Option(None, "--kind",
                                        help="doppler or range_rate, when the file holds both (default: doppler)."),
    reweight: bool = typer.Option(
        True, "--reweight/--no-reweight",
        help="Pointwise: scale the sample sigmas to their actual scatter (sqrt of the variance factor, when above "
             "1.5) before weighing them against the a-priori."),
    covariance: Covariance = typer.Option(
        Covariance.profile, "--covariance",
        help="Pointwise without --circular: profile = the linear covariance plus the curvature along the directions "
             "the pass cannot see (5 extra solves per direction); linear = the inverse normal matrix only."),
    noise: Noise = typer.Option(
        Noise.auto, "--noise",
        help="Noise model of the samples (pointwise): auto = chosen per pass by REML among white, AR(1) "
             "(exponentially correlated), random walk of the transmitter frequency (one-way) and both, then GLS; "
             "white = independent samples (the plain weighted fit); or that model. See docs/refine.md."),
    oscillator_noise: Optional[float] = OscillatorNoiseOpt,
    time_tag_sigma: Optional[float] = typer.Option(
        None, "--time-tag-sigma", metavar="S", min=0.0,
        help="1-sigma uncertainty of the station's time tags (s), added to the covariance (pointwise): one pass "
             "cannot see a time-tag offset (it is the orbit shifted along-track). Default: the station's "
             "time_sigma_s in the stations table (none: exact tags); given, it wins (0 = exact). "
             "See docs/refine.md."),
    horizon: float = HorizonOpt,
    max_iterations: int = typer.Option(30, "--max-iterations", min=1, help="Gauss-Newton iterations at most."),
    clip: float = typer.Option(4.0, "--clip", metavar="K", min=0.0,
                               help="Pointwise: edit samples beyond K x max(1, WRMS) sigmas. 0: off."),
    quadrature_order: int = typer.Option(16, "--quadrature-order", metavar="N", min=2,
                                         help="Integral: Gauss-Legendre nodes per panel."),
    quadrature_panel: float = typer.Option(30.0, "--quadrature-panel", metavar="S", min=1e-3,
                                           help="Integral: longest quadrature panel, s."),
    max_gap: str = typer.Option("30", "--max-gap", metavar="S",
                                help="Integral: data gaps longer than S s (or 30s, 2m) are left out of the integral."),
    force=ForceOpt,
    earth=EarthOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    range_rate_model: Optional[RangeRateModel] = PassRangeRateModelOpt,
    output_epoch: OutputEpoch = typer.Option(
        OutputEpoch.traverse, "--output-epoch",
        help="Epoch of the state written by -o: the traverse point (default) or the stale state's epoch; "
             "the file holds the other one too."),
    residuals: Optional[str] = typer.Option(None, "--residuals", metavar="FILE",
                                            help="Write the residuals at the samples (Parquet, or CSV by the suffix)."),
    opm: Optional[str] = typer.Option(None, "--opm", metavar="FILE",
                                      help="Also write the state written by -o as a CCSDS OPM (KVN) with its "
                                           "covariance and a COMMENT QUALITY line."),
    object_name: str = OpmObjectNameOpt,
    object_id: str = OpmObjectIdOpt,
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png",
                                       help="Plot the data with the refined model, the residuals and what the pass "
                                            "cannot see (needs matplotlib: pip install 'trackproc[plot]')."),
    as_json: bool = JsonSummaryOpt,
    strict: bool = StrictOpt,
    output: Optional[str] = OutputOpt,
) -> None:
    """Refine a stale orbit state from one Doppler (or range-rate) pass of one station, one- or
    two-way, at the traverse point of the pass (seed 004), and write a state file with the
    covariance, the same state at the stale epoch, the constraint residuals, an observability
    report (what one pass cannot see, in radial/along/cross-track terms), the residuals and the
    iterations.

    A one-screen summary goes to stderr. The state file carries a ``quality`` verdict (ok,
    suspect, rejected) with its reasons; when the pass cannot improve the stale state, the
    stale state is kept with its covariance (quality: refused). Exit status 1 when the
    refinement fails (no convergence, rank deficiency) or its verdict is 'rejected' (or
    'suspect' with --strict; the output is written), 2 for invalid input.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc ingest sample_data/doppler_pass.csv --stations sample_data/stations.csv \\
            --carrier-hz 2.2e9 --mode one-way -o pass.parquet
        trackproc smooth pass.parquet -o smoothed.parquet
        trackproc refine smoothed.parquet --initial sample_data/stale.json -o refined.json

        trackproc refine pass.parquet --initial sample_data/stale.json --doppler-bias offset+drift \\
            --residuals res.csv -o -

        trackproc refine smoothed.parquet --initial sample_data/stale.json --cost integral --circular \\
            -o seed004.json

    \f
    Over 100 lines because it declares the options (each with its help); the work is in
    pipeline/refine/ (run), with the reading and writing around it here.
    """
    from trackproc.io.validate import parse_duration

    max_gap = parse_duration(max_gap, "--max-gap")
    if not max_gap >= 1e-3:
        raise typer.BadParameter(f"{max_gap:g} s is below the minimum 0.001 s", param_hint="--max-gap")
    out = resolve_output(output, "output state file")
    if out == "-" and "-" in (residuals, opm):
        raise typer.BadParameter("stdout already carries the state file; give --residuals/--opm a file",
                                 param_hint="--residuals/--opm")
    if residuals == "-" and opm == "-":
        raise typer.BadParameter("--residuals and --opm cannot both go to stdout", param_hint="--residuals/--opm")
    sigmas = named_values(apriori_sigma, "--apriori-sigma")
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    if plot is not None:
        from trackproc.pipeline.plotting import require_matplotlib

        require_matplotlib()

    from trackproc.io.atomic import is_stdio
    from trackproc.io.eop import earth_orientation
    from trackproc.io.passfile import read_pass_table
    from trackproc.io.residuals import write_residuals
    from trackproc.io.stations import read_stations
    from trackproc.io.statefile import format_epoch, write_state
    from trackproc.pipeline.orbit_source import initial_state
    from trackproc.pipeline.refine import RefineOptions, refine
    from trackproc.report.refine_text import summary_text

    if force.value == "full":
        raise typer.BadParameter("refine fits one pass with the Taylor engine: two-body or j2 (--force full: "
                                 "propagate, simulate, accuracy, estimate)", param_hint="--force")
    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    source = "<stdin>" if is_stdio(input) else input
    table = read_pass_table(input)
    state0 = initial_state(initial, [(source, table)], orientation)
    station_table = read_stations(stations) if stations is not None else None
    options = RefineOptions(
        cost=cost.value, circular=circular, circular_tolerance=circular_tolerance,
        doppler_bias=doppler_bias.value if doppler_bias else None, apriori=apriori, apriori_sigma=sigmas,
        force=force.value, earth=earth.value, range_rate_model=range_rate_model.value if range_rate_model else None,
        max_iterations=max_iterations, clip=clip if clip > 0 else None, pass_id=pass_id,
        kind=kind.value if kind else None, quadrature_order=quadrature_order, quadrature_panel_s=quadrature_panel,
        max_gap_s=max_gap, reweight=reweight, covariance=covariance.value, noise=noise.value,
        oscillator_noise=oscillator_noise, time_tag_sigma_s=time_tag_sigma, horizon_days=horizon)
    result = refine(table, state0, station_table, options, orientation, source=source)

    state = result.state if output_epoch is OutputEpoch.traverse else result.stale_epoch_state
    write_state(state, out, force=force.value, eop_source=orientation.source)
    if opm is not None:
        from trackproc.io.opm import write_opm

        write_opm(state, opm, object_name=object_name, object_id=object_id,
                  comments=[f"trackproc refine, {cost.value} cost, pass {result.state.extra['refinement']['pass_id']}"])
    if residuals is not None:
        meta = {"epoch": format_epoch(result.state.epoch), "parameters": result.names, "command": "refine",
                "cost": cost.value, "force_model": force.value, "range_rate_model": result.problem.range_rate_model,
                "sources": [source]}
        write_residuals(result.residuals, residuals, meta)
    if plot is not None:
        from trackproc.io.atomic import write_bytes
        from trackproc.report.plots import refine_png

        write_bytes(plot, refine_png(result.residuals, result.state.diagnostics))
    from trackproc.cli.common import report_solution

    report_solution(result, "refine", as_json, strict, summary_text)
