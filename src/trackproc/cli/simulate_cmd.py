"""``trackproc simulate``: tracking passes of a known orbit (the test bench of every command)."""

from __future__ import annotations

import logging
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.force_options import ForceSettings, force_options
from trackproc.cli.common import (DopplerMode, Dut1Opt, EarthOpt, EopOpt, ForceOpt, OutputOpt, RangeRateModelOpt,
                                  TableFormat, resolve_output, table_format_for)

log = logging.getLogger("trackproc")

KIND_NAMES = "range,range_rate,doppler,elevation,azimuth"


@app.command("simulate")
@force_options
def simulate_command(
    state: Optional[str] = typer.Option(None, "--state", metavar="STATE.json",
                                        help="Initial state file (JSON; GCRF, EME2000, TEME or ITRF)."),
    tle: Optional[str] = typer.Option(None, "--tle", metavar="FILE",
                                      help="Or a TLE (2 or 3 lines): its SGP4 state at --start is the initial state."),
    stations: str = typer.Option(..., "--stations", metavar="STATIONS.csv",
                                 help="Stations table: station, lat_deg, lon_deg, height_m."),
    start: Optional[str] = typer.Option(None, "--start", metavar="ISO",
                                        help="First sample time, UTC ISO 8601 (default: the state's epoch)."),
    duration: Optional[str] = typer.Option(None, "--duration", metavar="S",
                                           help="Span to simulate, s, or with a unit: 90s, 45m, 6h, 2d (required unless --ballistic)."),
    step: str = typer.Option("10", "--step", metavar="S", help="Sample spacing, s, or with a unit: 90s, 45m, 6h, 2d."),
    elevation_mask_deg: float = typer.Option(10.0, "--elevation-mask-deg",
                                             help="Samples below this elevation are not seen, deg."),
    kinds: str = typer.Option(KIND_NAMES, "--kinds", help="Comma list of measurement kinds to write."),
    carrier_hz: float = typer.Option(2.2e9, "--carrier-hz", metavar="F", help="Nominal carrier frequency, Hz."),
    mode: DopplerMode = typer.Option(DopplerMode.one_way, "--mode",
                                     help="one-way (satellite transmits) or two-way (round trip; range = half of it)."),
    sigma_range_m: float = typer.Option(10.0, "--sigma-range-m", help="Range noise, m (0 = noiseless)."),
    sigma_range_rate_m_s: float = typer.Option(0.01, "--sigma-range-rate-m-s",
                                               help="Range-rate noise, m/s (0 = noiseless)."),
    sigma_doppler_hz: float = typer.Option(0.1, "--sigma-doppler-hz", help="Doppler noise, Hz (0 = noiseless)."),
    sigma_angle_deg: float = typer.Option(0.01, "--sigma-angle-deg",
                                          help="Azimuth/elevation noise, deg (0 = noiseless)."),
    range_bias: List[str] = typer.Option([], "--range-bias", metavar="STATION=METRES",
                                         help="Range bias added at a station (repeatable)."),
    freq_offset_hz: float = typer.Option(0.0, "--freq-offset-hz",
                                         help="Frequency offset added to every Doppler sample, Hz."),
    freq_drift_hz_s: float = typer.Option(0.0, "--freq-drift-hz-s", help="Frequency drift from --start, Hz/s."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, max=2**63 - 1, help="Random seed (same seed, same output)."),
    force=ForceOpt,
    earth=EarthOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    range_rate_model=RangeRateModelOpt,
    fmt: Optional[TableFormat] = typer.Option(
        None, "--format", help="Output format (default: from the suffix; Arrow stream on stdout)."),
    wide: bool = typer.Option(False, "--wide",
                              help="Write a wide CSV (time, station, range_m, range_rate_m_s, doppler_hz, "
                                   "elevation_deg, azimuth_deg) as a station would; ingest it with "
                                   "--carrier-hz and --mode."),
    truth: Optional[str] = typer.Option(None, "--truth", metavar="TRUTH.json",
                                        help="Also write the true state at the start time (state file, GCRF)."),
    output: Optional[str] = OutputOpt,
    ballistic: Optional[str] = typer.Option(
        None, "--ballistic", metavar="NOMINAL.json",
        help="Instead: elevation/azimuth pass of a seed 003 ballistic trajectory (see trackproc detect).",
        rich_help_panel="Ballistic (seed 003)"),
    hypothesis: str = typer.Option("h0", "--hypothesis", metavar="h0|h1",
                                   help="With --ballistic: nominal (h0) or displaced (h1) trajectory.",
                                   rich_help_panel="Ballistic (seed 003)"),
    displacement_m: Optional[float] = typer.Option(None, "--displacement-m", metavar="D",
                                                   help="With --ballistic --hypothesis h1: displacement, m "
                                                        "(default: the nominal file's).",
                                                   rich_help_panel="Ballistic (seed 003)"),
    force_settings: ForceSettings = None,
) -> None:
    """Simulate tracking passes of a known orbit: range, range-rate (one-way light time), Doppler,
    azimuth and elevation, with noise, range biases and a frequency offset/drift.

    The orbit is propagated by DOP853 at rtol 1e-13 (two-body or J2); stations by IAU 2006/2000A.
    Samples above the elevation mask form passes numbered STATION-001, -002, ...

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc simulate --state sample_data/truth.json --stations sample_data/stations.csv \\
            --duration 86400 --step 10 --seed 1 --range-bias ZHY=25 --truth truth_at_start.json \\
            -o passes.parquet

        trackproc simulate --tle sample_data/iss.tle --stations sample_data/stations.csv --duration 21600 \\
            | trackproc ingest - | trackproc info -

    \f
    Over 100 lines because it declares the options (each with its help); the work is in
    pipeline/simulate, with the reading and writing around it here.
    """
    from trackproc.io.validate import parse_duration

    duration = None if duration is None else parse_duration(duration, "--duration")
    step = parse_duration(step, "--step")
    if ballistic is not None:
        return _simulate_ballistic(ballistic, hypothesis, displacement_m, stations, step, elevation_mask_deg, kinds,
                                   sigma_angle_deg, seed, eop, dut1, fmt, output,
                                   ignored={"--state": state, "--tle": tle, "--start": start, "--duration": duration,
                                            "--truth": truth, "--wide": wide or None})
    if duration is None:
        raise typer.BadParameter("missing option (required unless --ballistic)", param_hint="--duration")
    if (state is None) == (tle is None):
        raise typer.BadParameter("give exactly one of --state STATE.json or --tle FILE", param_hint="--state/--tle")
    if wide and fmt is not None and fmt != TableFormat.csv:
        raise typer.BadParameter("--wide writes CSV; drop --format or use --format csv", param_hint="--wide")
    out = resolve_output(output, "output pass file")
    out_format = TableFormat.csv if wide else table_format_for(out, fmt)

    from trackproc.errors import InputError
    from trackproc.io.atomic import write_text
    from trackproc.io.eop import earth_orientation
    from trackproc.io.passfile import PassTable, iso_times, write_pass_table
    from trackproc.io.stations import read_stations
    from trackproc.io.statefile import parse_epoch, read_state, write_state
    from trackproc.pipeline.simulate import SimulateOptions, simulate

    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    start_t = parse_epoch(start, column="--start") if start is not None else None
    if state is not None:
        initial = read_state(state, orientation)
    else:
        from trackproc.io.tle import read_tle, tle_state

        initial = tle_state(read_tle(tle), at=start_t, eop=orientation)
    _check_extent(initial.epoch, start_t, duration, step, carrier_hz)
    table = read_stations(stations)
    biases = {}
    for item in range_bias:
        name, sep, value = item.partition("=")
        try:
            biases[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not name.strip():
            raise InputError("invalid range bias", column="--range-bias", found=item, expected="STATION=METRES")
    kind_list = tuple(k.strip() for k in kinds.split(",") if k.strip())
    options = SimulateOptions(
        duration_s=duration, step_s=step, start=start_t, elevation_mask_deg=elevation_mask_deg, kinds=kind_list,
        carrier_hz=carrier_hz, mode=mode.value, sigma_range_m=sigma_range_m,
        sigma_range_rate_m_s=sigma_range_rate_m_s, sigma_doppler_hz=sigma_doppler_hz,
        sigma_angle_deg=sigma_angle_deg, range_bias_m=biases, freq_offset_hz=freq_offset_hz,
        freq_drift_hz_s=freq_drift_hz_s, seed=seed, force=force.value, earth=earth.value,
        range_rate_model=range_rate_model.value,
        force_model=force_settings.model(force.value, initial.epoch, orientation, initial if state else None))
    result = simulate(initial, table, options, orientation)

    if truth is not None:
        write_state(result.truth, truth, force=force.value, eop_source=orientation.source)
    if wide:
        frame = result.wide()
        frame.insert(0, "time", iso_times(frame.pop("time")))
        write_text(out, frame.to_csv(index=False, lineterminator="\n", float_format=lambda v: repr(float(v))))
    else:
        write_pass_table(PassTable(result.frame, result.meta), out, out_format.value)
    frame = result.frame
    log.info("%d samples, %d passes, %d stations -> %s (%s)", len(frame), frame["pass_id"].nunique(),
             frame["station"].nunique(), "stdout" if out == "-" else out,
             "wide csv" if wide else out_format.value)


def _check_extent(epoch, start_t, duration, step, carrier_hz) -> None:
    """Refuse before computing what would run for hours (decades from the state's epoch) or
    cannot be a radio link (a carrier in GHz given as Hz)."""
    import numpy as np

    from trackproc.io.validate import check_carrier, check_rows, check_span

    check_carrier(carrier_hz)
    check_span(duration, "simulated span", column="--duration")
    if start_t is not None:
        offset = float((np.datetime64(start_t, "ns") - np.datetime64(epoch, "ns")) / np.timedelta64(1, "s"))
        check_span(abs(offset) + abs(duration), "propagation from the state's epoch to the end (--start + --duration)",
                   column="--start")
    if step > 0:
        check_rows(duration / step, "time steps", column="--step")


def _simulate_ballistic(nominal_path, hypothesis, displacement_m, stations, step, elevation_mask_deg, kinds,
                        sigma_angle_deg, seed, eop, dut1, fmt, output, ignored) -> None:
    """``simulate --ballistic``: pipeline.ballistic_sim (seed 003), same output conventions."""
    given = [flag for flag, value in ignored.items() if value is not None]
    if given:
        raise typer.BadParameter("not used with --ballistic (the nominal file sets the trajectory and times)",
                                 param_hint=given[0])
    if hypothesis.lower() not in ("h0", "h1"):
        raise typer.BadParameter(f"expected h0 or h1, got {hypothesis!r}", param_hint="--hypothesis")
    out = resolve_output(output, "output pass file")
    out_format = table_format_for(out, fmt)

    from trackproc.io.eop import earth_orientation
    from trackproc.io.passfile import PassTable, write_pass_table
    from trackproc.io.stations import read_stations
    from trackproc.pipeline.ballistic_sim import BallisticOptions, simulate_ballistic
    from trackproc.pipeline.detect import read_nominal

    nominal = read_nominal(nominal_path)
    orientation = None
    if nominal.model == "3d":
        orientation, warning = earth_orientation(eop, dut1)
        if warning:
            log.warning(warning)
    options = BallisticOptions(hypothesis=hypothesis.lower(), displacement_m=displacement_m, step_s=step,
                               elevation_mask_deg=elevation_mask_deg, sigma_angle_deg=sigma_angle_deg, seed=seed,
                               kinds=tuple(k.strip() for k in kinds.split(",") if k.strip()))
    result = simulate_ballistic(nominal, read_stations(stations), options, orientation)
    write_pass_table(PassTable(result.frame, result.meta), out, out_format.value)
    log.info("ballistic %s pass, %d samples at %s -> %s (%s)", hypothesis.upper(), len(result.frame), result.station,
             "stdout" if out == "-" else out, out_format.value)
