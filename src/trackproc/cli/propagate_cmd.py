"""``trackproc propagate``: a state file or TLE to an ephemeris (a pass predictor with --at-station)."""

from __future__ import annotations

import logging
from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.force_options import ForceSettings, force_options
from trackproc.cli.common import (
    Dut1Opt,
    EarthOpt,
    EopOpt,
    OutputOpt,
    RangeRateModelOpt,
    TableFormat,
    resolve_output,
    table_format_for,
)

log = logging.getLogger("trackproc")


class OrbitForce(str, Enum):
    sgp4 = "sgp4"
    two_body = "two-body"
    j2 = "j2"
    full = "full"


#: ``--force`` of commands taking a STATE|TLE (default: sgp4 for a TLE, j2 for a state).
OrbitForceOpt = typer.Option(None, "--force",
                             help="sgp4 (default for a TLE: SGP4 at every time), j2 (default for a state), "
                                  "two-body or full (gravity field, Sun, Moon, SRP, drag: see the force-model "
                                  "options); j2/two-body/full on a TLE integrate from its SGP4 state at the first "
                                  "requested time.")


class EphemerisFormat(str, Enum):
    parquet = "parquet"
    arrow = "arrow"
    csv = "csv"
    oem = "oem"


def _format(output: str, requested: Optional[EphemerisFormat]) -> EphemerisFormat:
    """``--format``, else ``oem`` for a ``.oem``/``.kvn`` file (also when stdout is redirected to
    one), else the table format of :func:`table_format_for`."""
    if requested is not None:
        return requested
    target = output
    if output == "-":
        from trackproc.cli.common import _stdout_file

        target = _stdout_file() or "-"
    if Path(target).suffix.lower() in (".oem", ".kvn"):
        return EphemerisFormat.oem
    return EphemerisFormat(table_format_for(output, None).value)


@app.command("propagate")
@force_options
def propagate_command(
    state: str = typer.Argument(..., metavar="STATE.json|TLE|metadata[:PASS]",
                                help="Initial state (JSON state file, any supported frame) or a TLE; - for stdin; "
                                     "'metadata' with --at: the TLE stored in that pass file (DopTrack); "
                                     "'metadata:PASS': the TLE stored in PASS (its stations serve --at-station)."),
    span: Optional[str] = typer.Option(None, "--span", metavar="S",
                                       help="Span from the start, s, or with a unit: 90s, 45m, 6h, 2d (negative: backwards in time)."),
    step: Optional[str] = typer.Option(None, "--step", metavar="S", help="Output spacing, s, or with a unit: 90s, 45m, 6h, 2d (with --span)."),
    at: Optional[str] = typer.Option(None, "--at", metavar="PASSFILE",
                                     help="Instead of a grid: the sample times of a pass file."),
    start: Optional[str] = typer.Option(None, "--start", metavar="ISO",
                                        help="First grid time, UTC ISO 8601 (default: the state's or TLE's "
                                             "epoch)."),
    force: Optional[OrbitForce] = OrbitForceOpt,
    earth=EarthOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    tol: float = typer.Option(1e-15, "--tol", metavar="TOL",
                              help="Taylor tolerance per step (relative/absolute; 1e-15 ~ micrometres per pass); "
                                   "--force full: the DOP853 rtol when >= 2.2e-14, else 1e-12."),
    stm: bool = typer.Option(False, "--stm", help="Add the state transition matrix columns stm_1_1 .. stm_6_6."),
    at_station: Optional[str] = typer.Option(None, "--at-station", metavar="ID",
                                             help="Add predicted range, range-rate, azimuth, elevation at this "
                                                  "station (one-way light time)."),
    stations: Optional[str] = typer.Option(None, "--stations", metavar="STATIONS.csv",
                                           help="Stations table (default with --at: the pass file's stations)."),
    carrier_hz: Optional[float] = typer.Option(None, "--carrier-hz", metavar="F",
                                               help="With --at-station: add doppler_hz = -F range_rate / c."),
    range_rate_model=RangeRateModelOpt,
    visible_only: bool = typer.Option(False, "--visible-only",
                                      help="With --at-station: keep only rows above --elevation-mask-deg."),
    elevation_mask_deg: float = typer.Option(10.0, "--elevation-mask-deg", metavar="DEG",
                                             help="Elevation mask of --visible-only, deg."),
    object_name: Optional[str] = typer.Option(None, "--object-name", help="OEM OBJECT_NAME (default: the TLE "
                                                                          "name, else UNKNOWN)."),
    object_id: Optional[str] = typer.Option(None, "--object-id", help="OEM OBJECT_ID (default: the TLE's "
                                                                      "international designator, else UNKNOWN)."),
    compare: Optional[str] = typer.Option(
        None, "--compare", metavar="CPF",
        help="Also compare the orbit with a reference ephemeris (ILRS CPF): distance RMS, max and its radial/"
             "along/cross parts over the CPF's epochs, one JSON line on stderr (a state, not a TLE)."),
    fmt: Optional[EphemerisFormat] = typer.Option(
        None, "--format", help="parquet, arrow, csv or oem (CCSDS OEM KVN; default from the suffix; "
                               "Arrow stream on stdout)."),
    output: Optional[str] = OutputOpt,
    force_settings: ForceSettings = None,
) -> None:
    """Propagate an orbit state (two-body or J2, adaptive Taylor series) or a TLE (SGP4 at every
    output time, unless --force j2/two-body) and write its ephemeris:
    time, x_m .. vz_m_s in GCRF, optionally the STM, the propagated covariance (when the state
    file has one) and a station's predicted measurements.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc propagate sample_data/truth.json --span 86400 --step 60 -o day.parquet

        trackproc propagate sample_data/truth.json --span 600 --step 1 --at-station ZHY \\
            --stations sample_data/stations.csv --carrier-hz 2.2e9 --visible-only -o zhy.csv

        trackproc propagate sample_data/truth.json --at sample_data/multistation.parquet --at-station ZHY \\
            -o zhy_predicted.csv

        trackproc propagate sample_data/truth.json --span 86400 --step 600 --format oem -o day.oem

        trackproc propagate sample_data/iss.tle --span -3600 --step 10 -o - > back.arrows

        trackproc propagate sample_data/iss.tle --span 86400 --step 10 --at-station CPH \\
            --stations sample_data/stations.csv --carrier-hz 145.87e6 --visible-only -o predicted.csv

        trackproc propagate sample_data/truth.json --at sample_data/multistation.parquet --at-station KIR \\
            --stations sample_data/multistation.parquet -o kir_predicted.csv

    Exit status: 0 ok; 2 bad options or input; 1 propagation failure (the Taylor run stopped,
    the orbit enters the Earth, or --visible-only found no pass).

    \f
    Over 100 lines because it declares the options (each with its help); the work is in
    dynamics/propagator and pipeline/propagate, with the reading and writing around it here.
    """
    from trackproc.io.validate import parse_duration

    span = None if span is None else parse_duration(span, "--span")
    step = None if step is None else parse_duration(step, "--step")
    if at is not None and (span is not None or step is not None):
        raise typer.BadParameter("give either --span S --step S or --at PASSFILE, not both", param_hint="--at")
    if at is None and (span is None or step is None):
        raise typer.BadParameter("give --span S and --step S, or --at PASSFILE", param_hint="--span/--step")
    from trackproc.pipeline.orbit_source import metadata_path

    if at is None and at_station is not None and stations is None and metadata_path(state) is None:
        raise typer.BadParameter("--at-station needs --stations STATIONS.csv (or --at PASSFILE or metadata:PASS with stations)",
                                 param_hint="--stations")
    for flag, given in (("--carrier-hz", carrier_hz is not None), ("--visible-only", visible_only)):
        if given and at_station is None:
            raise typer.BadParameter(f"{flag} needs --at-station ID", param_hint=flag)
    if state == "-" and at == "-":
        raise typer.BadParameter("only one input can come from stdin", param_hint="--at")
    out = resolve_output(output, "output ephemeris")
    out_format = _format(out, fmt)
    if out_format is EphemerisFormat.oem and (stm or at_station is not None):
        raise typer.BadParameter("an OEM holds states and covariances only; drop --stm/--at-station or use "
                                 "--format parquet, arrow or csv", param_hint="--format")

    from trackproc.io.eop import earth_orientation
    from trackproc.io.ephemeris import write_ephemeris
    from trackproc.io.statefile import parse_epoch
    from trackproc.pipeline.orbit_source import read_orbit, resolve_force
    from trackproc.pipeline.propagate import (
        PropagateOptions,
        oem_identity,
        pass_times,
        propagate,
        propagate_tle,
        resolve_station,
    )

    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    start_t = parse_epoch(start, column="--start") if start is not None else None
    at_times = None
    pass_table = None
    if at is not None:
        from trackproc.io.passfile import read_pass_table

        pass_table = read_pass_table(at)
        at_times = pass_times(pass_table, at_station)
    if state == "metadata":
        from trackproc.pipeline.orbit_source import OrbitInput, tle_from_pass_metadata

        if pass_table is None:
            raise typer.BadParameter("'metadata' (the TLE stored in a pass file) needs --at PASSFILE",
                                     param_hint="STATE")
        tle = tle_from_pass_metadata(pass_table, "<stdin>" if at == "-" else at)
        orbit = OrbitInput(tle=tle, source=tle.source)
    else:
        orbit = read_orbit(state, orientation)
    force_key = resolve_force(orbit, force.value if force is not None else None, allow_full=True)
    station = None
    if at_station is not None:
        table = None
        if stations is not None:
            from trackproc.io.stations import read_stations

            table = read_stations(stations)
        station = resolve_station(at_station, table, pass_table if pass_table is not None else orbit.pass_table)
    if orbit.state is not None:
        epoch0 = orbit.state.epoch
    else:
        from trackproc.io.tle import tle_epoch

        epoch0 = tle_epoch(orbit.tle)
    _check_extent(epoch0, start_t, span, step, at_times, carrier_hz, object_name, object_id)
    reference = None
    if compare is not None:                  # checked before anything is computed or written
        from trackproc.io.cpf import check_reference, read_cpf

        if force_key == "sgp4":
            from trackproc.errors import InputError

            raise InputError("--compare needs an integrated orbit", column="--compare",
                             found="a TLE evaluated by SGP4", expected="a state file, or --force j2/two-body")
        reference = read_cpf(compare)
        check_reference(reference, epoch0)
    options = PropagateOptions(
        span_s=span, step_s=step, start=start_t, at_times=at_times, force=force_key, earth=earth.value, tol=tol,
        stm=stm, station=station, carrier_hz=carrier_hz, range_rate_model=range_rate_model.value,
        visible_only=visible_only, elevation_mask_deg=elevation_mask_deg)
    if force_key == "sgp4":
        force_settings.model(force_key, None)              # full-only flags: a usage error
        result = propagate_tle(orbit.tle, options, orientation)
        initial = None
    else:
        initial = orbit.state
        if initial is None:
            from trackproc.io.tle import tle_epoch, tle_state

            # The first requested time: the grid's anchor (--start, else the epoch) or --at's first sample.
            from trackproc.io.statefile import format_epoch

            if at_times is not None and len(at_times):
                first = at_times.min()
            else:
                first = start_t if start_t is not None else tle_epoch(orbit.tle)
            initial = tle_state(orbit.tle, at=first, eop=orientation)

            options.force_note = (f"TLE integrated with {force_key} from its SGP4 state at {format_epoch(first)} "
                                  f"(--force {force_key}), not evaluated by SGP4")
            log.warning("%s", options.force_note)
        options.force_model = force_settings.model(force_key, initial.epoch, orientation, orbit.state)
        result = propagate(initial, options, orientation)

    oem_kwargs = {}
    if out_format is EphemerisFormat.oem:
        if initial is None:
            from trackproc.io.ephemeris import international_designator

            name = object_name or orbit.tle.name or "UNKNOWN"
            ident = object_id or international_designator(orbit.tle.line1) or "UNKNOWN"
            comment = "trackproc propagate: SGP4 at every epoch (TEME -> GCRF)"
        else:
            name, ident = oem_identity(initial, object_name, object_id)
            comment = (f"trackproc propagate: Taylor (DT) integration, tol {tol:g}" if force_key != "full" else
                       "trackproc propagate: DOP853 integration of the full force model")
        oem_kwargs = {"object_name": name, "object_id": ident, "comments": [comment]}
    write_ephemeris(result.ephemeris, out, out_format.value, **oem_kwargs)
    if compare is not None:
        _compare_with_cpf(compare, reference, initial, force_key, orientation, options.force_model)
    eph = result.ephemeris
    steps = (f"{result.trajectory.n_steps} {'DOP853' if force_key == 'full' else 'Taylor'} steps"
             if result.trajectory is not None else "SGP4")
    log.info("%d rows, %s .. %s, %s (%s) -> %s (%s)", len(eph), eph.meta["start"],
             eph.meta["end"], steps, eph.meta["force_model"],
             "stdout" if out == "-" else out, out_format.value)


def _compare_with_cpf(path, reference, initial, force_key, orientation, force_model=None) -> None:
    """``--compare CPF``: the summary of :func:`trackproc.pipeline.reference_orbit.compare_with_cpf`."""
    import json
    import sys

    from trackproc.errors import InputError
    from trackproc.pipeline.reference_orbit import compare_with_cpf

    if initial is None:
        raise InputError("--compare needs an integrated orbit", column="--compare", found="a TLE evaluated by SGP4",
                         expected="a state file, or --force j2/two-body")
    kwargs = {"force_model": force_model} if force_key == "full" else {}
    summary = compare_with_cpf(initial, reference, force=force_key, eop=orientation, propagate_kwargs=kwargs)
    summary.pop("distance_m")
    summary = {"reference": path, "force": force_key, **summary}
    sys.stderr.write(json.dumps(summary, sort_keys=True) + "\n")


def _check_extent(epoch, start_t, span, step, at_times, carrier_hz, object_name, object_id) -> None:
    """Refuse before computing what would run for hours (a span of decades), and names that
    would forge OEM lines."""
    import numpy as np

    from trackproc.io.validate import check_carrier, check_name, check_rows, check_span

    if carrier_hz is not None:
        check_carrier(carrier_hz)
    for flag, value in (("--object-name", object_name), ("--object-id", object_id)):
        if value is not None:
            check_name(value, "OEM " + flag[2:].replace("-", " "), column=flag)
    offset = 0.0
    if start_t is not None:
        offset = float((np.datetime64(start_t, "ns") - np.datetime64(epoch, "ns")) / np.timedelta64(1, "s"))
    if span is not None:
        check_span(span, "propagation span", column="--span")
        check_span(abs(offset) + abs(span), "propagation from the state's epoch (--start + --span)", column="--start")
        if step is not None and step != 0 and np.isfinite(step):
            check_rows(abs(span / step), "output rows", column="--step")
    if at_times is not None and len(at_times):
        times = np.asarray(at_times).astype("datetime64[ns]")
        far = float(np.max(np.abs((times - np.datetime64(epoch, "ns")) / np.timedelta64(1, "s"))))
        check_span(far, "propagation from the state's epoch to the pass", column="--at")


__all__ = ["propagate_command", "EphemerisFormat", "TableFormat"]
