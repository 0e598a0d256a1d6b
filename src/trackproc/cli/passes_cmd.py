"""``trackproc passes``: the pass schedule of a state or TLE over ground stations."""

from __future__ import annotations

import logging
from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.common import Dut1Opt, EarthOpt, EopOpt, OutputOpt, RangeRateModelOpt
from trackproc.cli.force_options import ForceSettings, force_options, full_force_model
from trackproc.cli.propagate_cmd import OrbitForce, OrbitForceOpt

log = logging.getLogger("trackproc")


class ScheduleFormat(str, Enum):
    csv = "csv"
    json = "json"
    md = "md"


@app.command("passes")
@force_options
def passes_command(
    orbit: str = typer.Argument(..., metavar="STATE.json|TLE|PASS",
                                help="Orbit state file or TLE; - for stdin; a pass file (or metadata:PASS): the TLE "
                                     "stored in its metadata (DopTrack)."),
    stations: Optional[str] = typer.Option(None, "--stations", metavar="STATIONS.csv|PASS",
                                           help="Stations table: station, lat_deg, lon_deg, height_m; or a pass "
                                                "file: its stations (default: the stations of the orbit's pass file)."),
    span: str = typer.Option(..., "--span", metavar="S", help="Span from the start: seconds, or 90m, 6h, 2d."),
    step: str = typer.Option("30", "--step", metavar="S",
                             help="Search grid, s, or 90s, 1m (maxima are refined; a pass shorter than the step is found)."),
    start: Optional[str] = typer.Option(None, "--start", metavar="ISO",
                                        help="Start, UTC ISO 8601 (default: the state's or TLE's epoch)."),
    min_elevation: float = typer.Option(0.0, "--min-elevation", metavar="DEG",
                                        help="AOS/LOS elevation mask, deg (geometric, no refraction)."),
    carrier_hz: Optional[float] = typer.Option(None, "--carrier-hz", metavar="F",
                                               help="Add one-way Doppler at AOS/TCA/LOS: -F range_rate / c."),
    force: Optional[OrbitForce] = OrbitForceOpt,
    earth=EarthOpt,
    range_rate_model=RangeRateModelOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    fmt: Optional[ScheduleFormat] = typer.Option(None, "--format",
                                                 help="csv, json or md (Markdown); default from the suffix, "
                                                      "else csv."),
    output: Optional[str] = OutputOpt,
    force_settings: ForceSettings = None,
) -> None:
    """Pass schedule per station: AOS, TCA (closest approach), LOS times, maximum elevation,
    azimuth, elevation and range at AOS/TCA/LOS, and Doppler there with --carrier-hz. A TLE is
    evaluated by SGP4 (default), a state integrated with J2. A pass file as the orbit (e.g. one
    ingested from DopTrack) gives the TLE and the stations its metadata holds.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc passes sample_data/truth.json --stations sample_data/stations.csv --span 1d \\
            --min-elevation 10 --carrier-hz 2.2e9 --format md -o -

        trackproc passes sample_data/iss.tle --stations sample_data/stations.csv --span 2d \\
            --carrier-hz 145.87e6 -o passes.csv

        trackproc passes sample_data/iss.tle --stations sample_data/multistation.parquet --span 6h -o -

    Exit status: 0 ok (also when no pass is found: an empty table, said on stderr); 2 bad
    options or input; 1 propagation failure.
    """
    from trackproc.errors import InputError
    from trackproc.io.validate import parse_duration

    step = parse_duration(step, "--step")
    from trackproc.io.atomic import write_text
    from trackproc.io.eop import earth_orientation
    from trackproc.io.statefile import parse_epoch
    from trackproc.io.stations import read_stations
    from trackproc.pipeline.orbit_source import read_orbit
    from trackproc.pipeline.passes import PassesOptions, find_passes, render
    from trackproc.cli.common import resolve_output

    if orbit == "-" and stations == "-":
        raise typer.BadParameter("only one input can come from stdin", param_hint="--stations")
    out = resolve_output(output, "output schedule")
    if fmt is None:
        suffix = Path(out).suffix.lower()
        fmt = {".json": ScheduleFormat.json, ".md": ScheduleFormat.md}.get(suffix, ScheduleFormat.csv)
    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    options = PassesOptions(span_s=parse_duration(span, "--span"), step_s=step,
                            start=parse_epoch(start, column="--start") if start is not None else None,
                            min_elevation_deg=min_elevation, carrier_hz=carrier_hz,
                            force=force.value if force is not None else None, earth=earth.value,
                            range_rate_model=range_rate_model.value)
    source = read_orbit(orbit, orientation)
    if stations is not None:
        table = read_stations(stations)
    elif source.pass_table is not None:
        table = source.pass_table.stations()
        if not table:
            raise InputError("no stations in the pass file's metadata", file=source.source, column="--stations",
                             expected="--stations STATIONS.csv, or a pass file ingested with its stations")
    else:
        raise InputError("no stations given", column="--stations", found=orbit,
                         expected="--stations STATIONS.csv (or a pass file), or a pass file as the orbit")
    options.force_model = full_force_model(force_settings, source, force, orientation)
    frame, meta = find_passes(source, table, options, orientation)
    if "note" in meta:
        log.info("%s", meta["note"])
    write_text(out, render(frame, meta, fmt.value))
    if len(frame) == 0:
        log.warning("no pass above %g deg at %s between %s and %s", min_elevation, ", ".join(sorted(table)),
                    meta["start"], meta["end"])
    else:
        log.info("%d passes (%s), %s .. %s -> %s", len(frame), ", ".join(
            f"{name}: {int((frame['station'] == name).sum())}" for name in sorted(table)), meta["start"], meta["end"],
            "stdout" if out == "-" else out)


__all__ = ["passes_command"]
