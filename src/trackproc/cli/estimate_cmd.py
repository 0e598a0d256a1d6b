"""``trackproc estimate``: orbit + biases by batch weighted least squares, error matrices out."""

from __future__ import annotations

import logging
from enum import Enum
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.force_options import ForceSettings, force_options
from trackproc import vocabulary
from trackproc.cli.common import (ComOffsetOpt, Dut1Opt, EarthOpt, EccentricitiesOpt, EopOpt, ForceOpt, HorizonOpt,
                                  JsonSummaryOpt, Noise, OpmObjectIdOpt, OpmObjectNameOpt, OscillatorNoiseOpt,
                                  OutputOpt, PassRangeRateModelOpt, RangeRateModel, SolidTidesOpt, StrictOpt,
                                  TroposphereOpt, WavelengthOpt, choices, named_values, read_passes_and_stations,
                                  resolve_output)

log = logging.getLogger("trackproc")


DopplerBias = choices("DopplerBias", vocabulary.ESTIMATE_DOPPLER_BIASES)



class BiasPer(str, Enum):
    pass_ = "pass"
    station = "station"


@app.command("estimate")
@force_options
def estimate_command(
    passes: List[str] = typer.Argument(..., metavar="PASS...",
                                       help="Pass files (Parquet, Arrow, CSV from ingest/simulate), or - for stdin."),
    initial: str = typer.Option(..., "--initial", metavar="STATE.json|TLE|metadata",
                                help="Initial state: a state file (GCRF, EME2000, TEME, ITRF) or a TLE; metadata = "
                                     "the TLE stored in the pass files (DopTrack; the newest)."),
    stations: Optional[str] = typer.Option(
        None, "--stations", metavar="STATIONS.csv",
        help="Stations table (station, lat_deg, lon_deg, height_m[, range_bias_m][, time_sigma_s]) or SINEX file "
             "(positions + velocities at the data's mid epoch); default: the pass files' metadata."),
    range_bias: bool = typer.Option(False, "--range-bias", help="Estimate a range bias for every station with ranges."),
    range_bias_station: List[str] = typer.Option(
        [], "--range-bias-station", metavar="STATION", help="Estimate a range bias for this station only (repeatable)."),
    doppler_bias: DopplerBias = typer.Option(
        "auto", "--doppler-bias",
        help="Transmitter frequency parameters: auto = an offset and a drift for each pass of one-way Doppler (the "
             "satellite's own oscillator), none for two-way links and range-rate; none; or offset / offset+drift on "
             "every pass with Doppler or range-rate samples."),
    doppler_bias_per: BiasPer = typer.Option(BiasPer.pass_, "--doppler-bias-per",
                                             help="One Doppler offset (drift) per pass or per station."),
    angle_bias: bool = typer.Option(False, "--angle-bias", help="Estimate azimuth and elevation biases per station."),
    station_time_bias: bool = typer.Option(
        False, "--station-time-bias",
        help="Estimate a time-tag offset per station (time_bias:STATION, s; tags late by it). A-priori sigma: the "
             "stations table's time_sigma_s or --apriori-sigma time_bias=S; one offset common to every station is "
             "the orbit moved along-track, so at least one station needs one. See docs/estimate.md."),
    station_time_bias_station: List[str] = typer.Option(
        [], "--station-time-bias-station", metavar="STATION",
        help="Estimate a time-tag offset for this station only (repeatable)."),
    estimate_force: List[str] = typer.Option(
        [], "--estimate-force", metavar="cr,cd,empirical-rtn",
        help="With --force full: estimate these force-model parameters (cr, cd, empirical-rtn = a constant "
             "radial/along-track/cross-track acceleration, empirical-xyz = one along the GCRF axes, "
             "empirical-xyz-rate = its growth per second, or single components empirical_r ... empirical_z_rate), "
             "from the "
             "model's values (--cr, --cd; accelerations 0); comma list, repeatable. A-priori: --apriori-sigma "
             "cr=0.5, empirical=1e-8."),
    noise: Noise = typer.Option(
        Noise.auto, "--noise",
        help="Noise model of each pass's Doppler/range-rate samples: auto = chosen per pass by REML among white, "
             "AR(1) and (one-way, with --doppler-bias) a random walk of the transmitter frequency, then GLS; white = "
             "independent samples; or that model. See docs/estimate.md."),
    oscillator_noise: Optional[float] = OscillatorNoiseOpt,
    apriori_sigma: List[str] = typer.Option(
        [], "--apriori-sigma", metavar="NAME=SIGMA",
        help="A-priori 1-sigma (SI units) of a parameter (x, vx, range_bias:KIR), a family (range_bias, "
             "doppler_offset) or position/velocity/state; repeatable."),
    apriori_initial: Optional[bool] = typer.Option(
        None, "--apriori-initial/--no-apriori-initial",
        help="Use the initial state's covariance as an a-priori constraint (a state without one, such as a TLE: "
             "refine's default element a-priori, along-track loose). A contradicted a-priori is scaled by the data, "
             "or the initial state is kept when the data's noise model is in doubt (quality: refused). Default: on "
             "for a TLE, off otherwise.", show_default=False),
    epoch: Optional[str] = typer.Option(None, "--epoch", metavar="ISO|initial|first",
                                        help="Solution epoch (default: the initial state's, a TLE's at the first "
                                             "sample; first = first sample; initial = the TLE's epoch)."),
    kinds: Optional[str] = typer.Option(None, "--kinds", metavar="KIND[,KIND]",
                                        help="Kinds to use: range, range_rate, doppler, azimuth, elevation (default all)."),
    horizon: float = HorizonOpt,
    max_iterations: int = typer.Option(20, "--max-iterations", min=1, help="Gauss-Newton iterations at most."),
    max_samples: int = typer.Option(200_000, "--max-samples", metavar="N", min=1,
                                    help="Refuse more samples than this over all pass files (memory grows by "
                                         "~3.5 kB a sample: 200,000 is ~1 GB; raise it for more)."),
    clip: float = typer.Option(4.0, "--clip", metavar="K", min=0.0,
                               help="Edit samples beyond K x max(1, WRMS) sigmas (iterated, flagged). 0: off."),
    troposphere: str = TroposphereOpt,
    com_offset: float = ComOffsetOpt,
    wavelength_nm: Optional[float] = WavelengthOpt,
    solid_tides: Optional[bool] = SolidTidesOpt,
    eccentricities: Optional[str] = EccentricitiesOpt,
    force=ForceOpt,
    earth=EarthOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    range_rate_model: Optional[RangeRateModel] = PassRangeRateModelOpt,
    compare_doppler_only: bool = typer.Option(
        False, "--compare-doppler-only", help="Seed 002: also solve without the ranges; print both motion blocks."),
    two_stage: bool = typer.Option(False, "--two-stage",
                                   help="Seed 002 two-stage method: per-pass offsets, then bias-corrected ranges."),
    opm: Optional[str] = typer.Option(None, "--opm", metavar="FILE", help="Also write a CCSDS OPM (KVN) with covariance."),
    object_name: str = OpmObjectNameOpt,
    object_id: str = OpmObjectIdOpt,
    residuals: Optional[str] = typer.Option(None, "--residuals", metavar="FILE",
                                            help="Write the residuals (Parquet, or CSV by the .csv suffix)."),
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png",
                                       help="Plot the residuals per kind in their units, RMS per pass (needs matplotlib: "
                                            "pip install 'trackproc[plot]')."),
    as_json: bool = JsonSummaryOpt,
    strict: bool = StrictOpt,
    output: Optional[str] = OutputOpt,
    force_settings: ForceSettings = None,
) -> None:
    """Estimate the orbit state at an epoch and the selected biases from one or more passes
    (batch weighted least squares with per-station range biases, seed 002), and write a state
    file with every parameter, its sigma, the full covariance and the diagnostics.

    A one-screen summary goes to stderr. The state file (and the OPM, as a COMMENT) carries a
    ``quality`` verdict (ok, suspect, rejected) with its reasons (a-priori conflict and its
    adaptation, refusal that keeps the initial state, variance factor, residual whiteness, the
    pass that dominates the misfit, edited samples). Exit status 1 when the
    estimation fails (too few data, rank deficiency with the unobservable combinations named,
    no convergence) or its verdict is 'rejected' (or 'suspect' with --strict; the outputs are
    written).

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc estimate sample_data/multistation.parquet --initial sample_data/truth.json --range-bias \\
            --opm solution.opm --residuals residuals.csv -o solution.json

        trackproc simulate --state sample_data/truth.json --stations sample_data/stations.csv \\
            --duration 21600 --range-bias KIR=100 --seed 1 \\
            | trackproc estimate - --initial sample_data/truth.json --range-bias -o -

    \f
    Over 100 lines because it declares the options (each with its help); the work is in
    pipeline/estimate/, with the reading and writing around it here.
    """
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    if sum(p == "-" for p in passes) > 1:
        raise typer.BadParameter("stdin (-) can be read once", param_hint="PASS")
    out = resolve_output(output, "output state file")
    taken = [f for f in (opm, residuals) if f == "-"]
    if taken and out == "-":
        raise typer.BadParameter("stdout already carries the state file; give --opm/--residuals a file",
                                 param_hint="--opm/--residuals")
    if range_bias and range_bias_station:
        raise typer.BadParameter("give --range-bias (every station) or --range-bias-station, not both",
                                 param_hint="--range-bias")
    if station_time_bias and station_time_bias_station:
        raise typer.BadParameter("give --station-time-bias (every station) or --station-time-bias-station, not both",
                                 param_hint="--station-time-bias")
    sigmas = named_values(apriori_sigma, "--apriori-sigma")
    kind_list = [k.strip() for k in kinds.split(",") if k.strip()] if kinds else None

    from trackproc.io.atomic import write_bytes
    from trackproc.io.eop import earth_orientation
    from trackproc.io.opm import write_opm
    from trackproc.io.residuals import write_residuals
    from trackproc.io.statefile import format_epoch, write_state
    from trackproc.pipeline.orbit_source import initial_state, tle_evaluation_epoch
    from trackproc.pipeline.estimate import EstimateOptions, estimate, require_matplotlib, summary_text
    from trackproc.report.plots import residuals_png

    if plot is not None:
        require_matplotlib()
    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    tables, station_table = read_passes_and_stations(passes, stations, eccentricities)
    n_samples = sum(t.n_rows for _, t in tables)
    if n_samples > max_samples:
        raise typer.BadParameter(f"{n_samples} samples in the pass files, more than {max_samples} (memory grows by "
                                 "~3.5 kB a sample); raise --max-samples, or thin the passes", param_hint="--max-samples")
    # a TLE is evaluated by SGP4 at the solution epoch (default: the first sample)
    state0 = initial_state(initial, tables, orientation, at=tle_evaluation_epoch(epoch, tables))
    options = EstimateOptions(
        range_bias=True if range_bias else list(range_bias_station), doppler_bias=doppler_bias.value,
        doppler_bias_per=doppler_bias_per.value, angle_bias=angle_bias, apriori_sigma=sigmas,
        station_time_bias=True if station_time_bias else list(station_time_bias_station),
        apriori_initial=apriori_initial, force=force.value, earth=earth.value,
        range_rate_model=range_rate_model.value if range_rate_model else None, max_iterations=max_iterations,
        horizon_days=horizon,
        clip=clip if clip > 0 else None, epoch=epoch, kinds=kind_list, compare_doppler_only=compare_doppler_only,
        two_stage=two_stage, noise=noise.value, oscillator_noise=oscillator_noise,
        troposphere=troposphere, com_offset_m=com_offset, wavelength_nm=wavelength_nm, solid_tides=solid_tides,
        estimate_force=list(estimate_force),
        force_model=force_settings.model(force.value, state0.epoch, orientation, state0))
    result = estimate(tables, state0, station_table, options, orientation)
    corrections = {}
    for b in result.problem.modifiers:
        if not b.names and b.rows.size:         # driver-free: the known range corrections
            label = repr(b.modifier)
            corrections[label] = corrections.get(label, 0) + int(b.rows.size)
    if corrections:
        log.info("range corrections: %s", "; ".join(f"{k} on {n} samples" for k, n in corrections.items()))

    png = residuals_png(result.residuals) if plot is not None else None
    write_state(result.state, out, force=force.value, eop_source=orientation.source)
    if opm is not None:
        write_opm(result.state, opm, object_name=object_name, object_id=object_id,
                  comments=[f"trackproc estimate, range-rate model {result.problem.range_rate_model}"])
    if residuals is not None:
        meta = {"epoch": format_epoch(result.state.epoch), "parameters": result.solution.names,
                "force_model": force.value, "range_rate_model": result.problem.range_rate_model,
                "sources": sorted(str(s) for s in set(result.problem.sources))}
        write_residuals(result.residuals, residuals, meta)
    if png is not None:
        write_bytes(plot, png)
    from trackproc.cli.common import report_solution

    report_solution(result, "estimate", as_json, strict, summary_text)
