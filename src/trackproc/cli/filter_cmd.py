"""``trackproc filter``: sequential orbit determination (extended Kalman filter, RTS smoother)."""

from __future__ import annotations

import logging
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.force_options import ForceSettings, force_options
from trackproc import vocabulary
from trackproc.cli.common import (ComOffsetOpt, Dut1Opt, EarthOpt, EccentricitiesOpt, EopOpt, ForceOpt,
                                  HorizonOpt, JsonSummaryOpt, Noise, OutputOpt, PassRangeRateModelOpt, RangeRateModel,
                                  SolidTidesOpt, StrictOpt, TroposphereOpt, WavelengthOpt, choices, named_values,
                                  read_passes_and_stations, resolve_output)

log = logging.getLogger("trackproc")

DopplerBias = choices("DopplerBias", vocabulary.ESTIMATE_DOPPLER_BIASES)
BiasPer = choices("BiasPer", ("pass", "station"))


def _snc(text: Optional[str]) -> tuple:
    if not text:
        return (0.0, 0.0, 0.0)
    parts = [p.strip() for p in text.split(",") if p.strip()]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise typer.BadParameter(f"found {text!r}; expected one density or R,T,N in m/s^2/sqrt(Hz)",
                                 param_hint="--snc-accel") from None
    if len(values) == 1:
        values *= 3
    if len(values) != 3:
        raise typer.BadParameter(f"found {len(values)} values; expected one or three (R,T,N)", param_hint="--snc-accel")
    return tuple(values)


#: The time constant of ``--dmc SIGMA`` without one, s.
DMC_DEFAULT_TAU_S = 3600.0


def _dmc(text: Optional[str]):
    """``SIGMA[,TAU]`` or ``R,T,N,TAU`` -> ``(sigma_r, sigma_t, sigma_n, tau)``; None without it."""
    if not text:
        return None
    parts = [p.strip() for p in text.split(",") if p.strip()]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 2, 4):
        raise typer.BadParameter(f"found {text!r}; expected SIGMA[,TAU] or R,T,N,TAU (m/s^2, s)", param_hint="--dmc")
    if len(values) == 1:
        values.append(DMC_DEFAULT_TAU_S)
    if len(values) == 2:
        values = [values[0]] * 3 + [values[1]]
    return tuple(values)


def _bias_gm(items: List[str]) -> dict:
    """``NAME=SIGMA,TAU`` options -> ``{NAME: (sigma, tau)}``; a usage error otherwise."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            pair = tuple(float(v) for v in value.split(","))
        except ValueError:
            pair = ()
        if not sep or not name.strip() or len(pair) != 2:
            raise typer.BadParameter(f"found {item!r}; expected NAME=SIGMA,TAU (the bias's unit, s)",
                                     param_hint="--bias-gm")
        if name.strip() in out:
            raise typer.BadParameter(f"{name.strip()} given twice", param_hint="--bias-gm")
        out[name.strip()] = pair
    return out


@app.command("filter")
@force_options
def filter_command(
    passes: List[str] = typer.Argument(..., metavar="PASS...",
                                       help="Pass files (Parquet, Arrow, CSV from ingest/simulate), or - for stdin."),
    initial: str = typer.Option(..., "--initial", metavar="STATE.json|TLE|metadata",
                                help="Initial state: a state file with a covariance (a previous filter run's output "
                                     "carries its biases and last measurement time: older passes are skipped), a "
                                     "TLE (refine's default element a-priori), or metadata (the pass files' TLE)."),
    stations: Optional[str] = typer.Option(None, "--stations", metavar="STATIONS.csv",
                                           help="Stations table or SINEX file; default: the pass files' metadata."),
    range_bias: bool = typer.Option(False, "--range-bias", help="A range bias state per station with ranges."),
    range_bias_station: List[str] = typer.Option([], "--range-bias-station", metavar="STATION",
                                                 help="A range bias state for this station only (repeatable)."),
    doppler_bias: DopplerBias = typer.Option("auto", "--doppler-bias",
                                             help="Transmitter frequency states, as estimate's --doppler-bias."),
    doppler_bias_per: BiasPer = typer.Option("pass", "--doppler-bias-per",
                                             help="One Doppler offset (drift) per pass or per station."),
    angle_bias: bool = typer.Option(False, "--angle-bias", help="Azimuth and elevation bias states per station."),
    estimate_force: List[str] = typer.Option([], "--estimate-force", metavar="cr,cd,empirical-rtn",
                                             help="With --force full: force-model parameters as states "
                                                  "(as estimate's --estimate-force)."),
    apriori_sigma: List[str] = typer.Option(
        [], "--apriori-sigma", metavar="NAME=SIGMA",
        help="Initial 1-sigma (SI units) of a parameter, a family (range_bias) or position/velocity/state; "
             "parameters without one start diffuse (1e4 x their scale: range bias 100 km)."),
    apriori_initial: Optional[bool] = typer.Option(
        None, "--apriori-initial/--no-apriori-initial", show_default=False,
        help="Start from the initial state's covariance (default when it has one; a TLE: its accuracy at its age, "
             "TLE differencing)."),
    snc_accel: Optional[str] = typer.Option(
        None, "--snc-accel", metavar="Q|R,T,N",
        help="State noise compensation: 1-sigma density of a white acceleration along radial, along-track, "
             "cross-track, in m/s^2/sqrt(Hz) (one value: all three). Default 0: no process noise."),
    bias_walk: List[str] = typer.Option(
        [], "--bias-walk", metavar="NAME=DENSITY",
        help="Random walk of a bias family or parameter (range_bias=1e-3 m/sqrt(s), doppler_offset=0.01 Hz/sqrt(s)); "
             "repeatable."),
    bias_gm: List[str] = typer.Option(
        [], "--bias-gm", metavar="NAME=SIGMA,TAU",
        help="First-order Gauss-Markov bias: steady-state 1-sigma SIGMA in the bias's unit and time constant TAU s "
             "(range_bias=0.5,86400; doppler_offset=20,3600 for the oscillator); repeatable."),
    bias_reset_per_pass: List[str] = typer.Option(
        [], "--bias-reset-per-pass", metavar="NAME",
        help="Restart a per-station bias (range_bias, az_bias, el_bias, or one parameter range_bias:KIR) from its "
             "a-priori at each new pass of its station; repeatable. Doppler offsets are per pass already "
             "(--doppler-bias-per pass)."),
    dmc: Optional[str] = typer.Option(
        None, "--dmc", metavar="SIGMA[,TAU]|R,T,N,TAU",
        help="Dynamic model compensation: empirical radial, along-track, cross-track accelerations estimated as "
             "first-order Gauss-Markov states, steady-state 1-sigma in m/s^2 and time constant in s (default "
             "3600). Needs --force full; adds --estimate-force empirical-rtn."),
    noise: Noise = typer.Option(
        Noise.auto, "--noise",
        help="Noise model of each pass's Doppler/range-rate samples, estimate's: auto (the default) = chosen per "
             "pass by REML, on the residuals of a first white smoother, among white, AR(1) and (one-way, with a "
             "Doppler offset) a random walk of the transmitter frequency, in sequential form (AR(1) a "
             "Gauss-Markov state of the pass, the walk on its offset); white = independent samples at their "
             "sigma; or that model. See docs/filter.md."),
    oscillator_noise: Optional[float] = typer.Option(
        None, "--oscillator-noise", metavar="HZ_PER_SQRT_S",
        help="Random walk of the transmitter frequency offset (Hz/sqrt(s)): --bias-walk doppler_offset=VALUE."),
    edit_sigma: float = typer.Option(5.0, "--edit-sigma", metavar="K", min=0.0,
                                     help="Edit a sample whose innovation is beyond K sigmas of its innovation "
                                          "variance (chi2 with 1 degree of freedom). 0: off."),
    smooth: bool = typer.Option(False, "--smooth", help="Rauch-Tung-Striebel smoother; the output is the smoothed "
                                                        "state (at --epoch, else the filter's first time)."),
    iterations: int = typer.Option(1, "--iterations", min=1,
                                   help="Sweeps of filter and smoother, each linearised about the previous sweep's "
                                        "smoothed states (needs --smooth); stops early when converged."),
    segment_gap: float = typer.Option(300.0, "--segment-gap", metavar="S", min=0.0,
                                      help="A gap between measurements longer than S seconds ends a tracking segment; "
                                           "the reference trajectory restarts from the filter's state there."),
    epoch: Optional[str] = typer.Option(None, "--epoch", metavar="ISO",
                                        help="Epoch of the written state (default: the last measurement; with "
                                             "--smooth the filter's first time)."),
    troposphere: str = TroposphereOpt,
    com_offset: float = ComOffsetOpt,
    wavelength_nm: Optional[float] = WavelengthOpt,
    solid_tides: Optional[bool] = SolidTidesOpt,
    eccentricities: Optional[str] = EccentricitiesOpt,
    kinds: Optional[str] = typer.Option(None, "--kinds", metavar="KIND[,KIND]", help="Kinds to use (default all)."),
    force=ForceOpt,
    earth=EarthOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    range_rate_model: Optional[RangeRateModel] = PassRangeRateModelOpt,
    history: Optional[str] = typer.Option(None, "--history", metavar="FILE.csv|FILE.oem",
                                          help="Every filtered (and smoothed) state with sigmas and covariance: CSV "
                                               "(every parameter), or CCSDS OEM with covariance blocks by the suffix "
                                               ".oem (the orbit; one segment per solution)."),
    object_name: str = typer.Option("UNKNOWN", "--object-name", metavar="NAME",
                                    help="OBJECT_NAME of an OEM --history."),
    object_id: str = typer.Option("UNKNOWN", "--object-id", metavar="ID", help="OBJECT_ID of an OEM --history."),
    residuals: Optional[str] = typer.Option(None, "--residuals", metavar="FILE",
                                            help="Innovations and residuals per sample (Parquet, or CSV by suffix)."),
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png",
                                       help="Plot the innovations per kind with their +-3 sigma bands and the "
                                            "position sigmas (R, T, N) over time (needs matplotlib: "
                                            "pip install 'trackproc[plot]')."),
    horizon: float = HorizonOpt,
    as_json: bool = JsonSummaryOpt,
    strict: bool = StrictOpt,
    output: Optional[str] = OutputOpt,
    force_settings: ForceSettings = None,
) -> None:
    """Sequential orbit determination: an extended Kalman filter over the passes in time order
    (the measurement models, bias modifiers and force models of estimate), with process noise,
    innovation editing and an optional RTS smoother; writes the state file schema estimate
    writes, with a 'filter' record and a quality verdict (innovation test, whiteness,
    filter-smoother test). A previous run's output as --initial carries the state, biases and
    covariance to tonight's passes.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc filter sample_data/multistation.parquet --initial sample_data/stale.json \\
            --range-bias --apriori-sigma range_bias=1000 --kinds range,range_rate -o filtered.json

        trackproc filter sample_data/multistation.parquet --initial sample_data/stale.json \\
            --range-bias --apriori-sigma range_bias=1000 --kinds range,range_rate --smooth --iterations 5 \\
            --history history.csv -o smoothed.json

    \f
    Over 100 lines because it declares the options (each with its help); the work is in
    pipeline/filter/ (result.filter_passes), with the reading and writing around it here.
    """
    if sum(p == "-" for p in passes) > 1:
        raise typer.BadParameter("stdin (-) can be read once", param_hint="PASS")
    out = resolve_output(output, "output state file")
    if out == "-" and "-" in (history, residuals):
        raise typer.BadParameter("stdout already carries the state file; give --history/--residuals a file",
                                 param_hint="--history/--residuals")
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    if range_bias and range_bias_station:
        raise typer.BadParameter("give --range-bias (every station) or --range-bias-station, not both",
                                 param_hint="--range-bias")
    sigmas = named_values(apriori_sigma, "--apriori-sigma")
    walks = named_values(bias_walk, "--bias-walk")
    if oscillator_noise is not None:
        walks.setdefault("doppler_offset", oscillator_noise)
    accel = _snc(snc_accel)
    dmc_values = _dmc(dmc)
    gm_biases = _bias_gm(bias_gm)
    forces_estimated = list(estimate_force)
    if dmc_values is not None:
        if force.value != "full":
            raise typer.BadParameter(f"found --force {force.value}; dynamic model compensation needs --force full "
                                     "(its accelerations are the full model's empirical-rtn)", param_hint="--dmc")
        from trackproc.pipeline.od.options import force_parameter_names

        have = force_parameter_names(forces_estimated)
        forces_estimated += [n for n in ("empirical_r", "empirical_t", "empirical_n") if n not in have]
    kind_list = [k.strip() for k in kinds.split(",") if k.strip()] if kinds else None

    from trackproc.io.atomic import write_bytes, write_text
    from trackproc.io.eop import earth_orientation
    from trackproc.io.statefile import parse_epoch, write_state
    from trackproc.pipeline.orbit_source import initial_state, tle_evaluation_epoch
    from trackproc.pipeline.filter import FilterOptions, filter_passes, summary_text
    from trackproc.pipeline.od import EstimateOptions
    from trackproc.isotime import iso_utc

    def format_epoch_ts(t):
        return iso_utc(t.tz_convert("UTC").tz_localize(None).to_datetime64())

    if plot is not None:
        from trackproc.pipeline.plotting import require_matplotlib

        require_matplotlib()
    out_epoch = parse_epoch(epoch, column="--epoch") if epoch else None
    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    tables, station_table = read_passes_and_stations(passes, stations, eccentricities)
    state0 = initial_state(initial, tables, orientation, at=tle_evaluation_epoch(None, tables))
    problem = EstimateOptions(
        range_bias=True if range_bias else list(range_bias_station), doppler_bias=doppler_bias.value,
        doppler_bias_per=doppler_bias_per.value, angle_bias=angle_bias, apriori_sigma=sigmas,
        apriori_initial=apriori_initial, horizon_days=horizon, force=force.value, earth=earth.value,
        range_rate_model=range_rate_model.value if range_rate_model else None, kinds=kind_list, noise=noise.value,
        estimate_force=forces_estimated, troposphere=troposphere, com_offset_m=com_offset,
        wavelength_nm=wavelength_nm, solid_tides=solid_tides,
        force_model=force_settings.model(force.value, state0.epoch, orientation, state0))
    options = FilterOptions(problem=problem, snc_accel=accel, bias_walk=walks, dmc=dmc_values, bias_gm=gm_biases,
                            bias_reset=tuple(bias_reset_per_pass),
                            edit_sigma=edit_sigma if edit_sigma > 0 else None, smooth=smooth, iterations=iterations,
                            segment_gap_s=segment_gap, output_epoch=out_epoch)
    result = filter_passes(tables, state0, station_table, options, orientation)
    png = None
    if plot is not None:
        from trackproc.report.plots import filter_png

        png = filter_png(result.innovations, result.sigma_history())
    write_state(result.state, out, force=force.value, eop_source=orientation.source)
    if history is not None:
        if history.lower().endswith(".oem"):
            write_text(history, result.history_oem(object_name=object_name, object_id=object_id))
        else:
            write_text(history, result.history().to_csv(index=False, float_format="%.17g"))
    if residuals is not None:
        frame = result.innovations.assign(time=result.innovations["time"].map(format_epoch_ts))
        if residuals.lower().endswith(".csv"):
            write_text(residuals, frame.to_csv(index=False, float_format="%.17g"))
        else:
            import io

            buf = io.BytesIO()
            result.innovations.to_parquet(buf, index=False)
            write_bytes(residuals, buf.getvalue())
    if png is not None:
        write_bytes(plot, png)
    from trackproc.cli.common import report_solution

    report_solution(result, "filter", as_json, strict, summary_text)
