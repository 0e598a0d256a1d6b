"""``trackproc ingest``: raw tracking files -> the canonical pass table."""

from __future__ import annotations

import itertools
import logging
from enum import Enum
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.common import DopplerMode, OutputOpt, TableFormat, resolve_output, table_format_for

log = logging.getLogger("trackproc")


class TdmTwoWayRange(str, Enum):
    one_way_equivalent = "one-way-equivalent"
    round_trip = "round-trip"


class Layout(str, Enum):
    auto = "auto"
    wide = "wide"
    long = "long"
    doptrack = "doptrack"
    aer = "aer"
    tdm = "tdm"
    crd = "crd"


@app.command("ingest")
def ingest_command(
    inputs: List[str] = typer.Argument(..., metavar="INPUT",
                                       help="CSV, Parquet, Arrow IPC, DopTrack CSV, Orekit .aer, CCSDS TDM or ILRS CRD (.npt/.crd); - for stdin."),
    stations: Optional[str] = typer.Option(
        None, "--stations", metavar="STATIONS.csv",
        help="Stations table: station, lat_deg, lon_deg, height_m [, range_bias_m]; or a SINEX file "
             "(positions + velocities, taken at the data's mid epoch). "
             "Optional when every input defines its stations (DopTrack sidecar, pass files)."),
    eccentricities: Optional[str] = typer.Option(
        None, "--eccentricities", metavar="ECC.snx",
        help="SINEX SITE/ECCENTRICITY file (e.g. ILRS ecc_une.snx) applied to the --stations SINEX positions."),
    carrier_hz: Optional[float] = typer.Option(
        None, "--carrier-hz", metavar="F",
        help="Nominal carrier frequency, Hz (required with Doppler samples unless the input gives it)."),
    mode: Optional[DopplerMode] = typer.Option(
        None, "--mode", help="Doppler link: one-way or two-way (required with Doppler samples)."),
    max_gap: str = typer.Option("300", "--max-gap", metavar="S",
                                help="Start a new pass after a gap longer than S seconds (or 90s, 5m, 1h)."),
    layout: Layout = typer.Option(Layout.auto, "--layout", help="Input layout (auto: detected)."),
    sidecar: Optional[str] = typer.Option(None, "--sidecar", metavar="FILE",
                                          help="DopTrack YAML sidecar (default: ../metadata/<name>.yml)."),
    tdm_two_way_range: TdmTwoWayRange = typer.Option(
        TdmTwoWayRange.one_way_equivalent, "--tdm-two-way-range",
        help="How a CCSDS TDM writes two-way RANGE: one-way-equivalent (as the spec's examples) or round-trip (halved)."),
    drop_invalid: bool = typer.Option(False, "--drop-invalid",
                                      help="Drop invalid samples (counts per reason on stderr) instead of failing."),
    sigma_range_m: Optional[float] = typer.Option(
        None, "--sigma-range-m",
        help="Range sigma, m, for samples without one (default 10); given, it also replaces the sigma of ILRS CRD "
             "normal points (by default their own precision, c/2 rms/sqrt(n) of record 11)."),
    sigma_range_rate_m_s: float = typer.Option(0.1, "--sigma-range-rate-m-s", help="Default range-rate sigma, m/s."),
    sigma_doppler_hz: float = typer.Option(1.0, "--sigma-doppler-hz", help="Default Doppler sigma, Hz."),
    sigma_angle_deg: float = typer.Option(0.01, "--sigma-angle-deg", help="Default azimuth/elevation sigma, deg."),
    fmt: Optional[TableFormat] = typer.Option(
        None, "--format", help="Output format (default: from the suffix; Arrow stream on stdout)."),
    output: Optional[str] = OutputOpt,
) -> None:
    """Validate raw passes and write the canonical pass table (SI units, UTC, sorted, passes numbered).

    Doppler sign convention: Doppler = received - nominal carrier; range-rate positive when
    receding (one-way: range_rate = -c*doppler/carrier).

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc ingest sample_data/doppler_pass.csv --stations sample_data/stations.csv \\
            --carrier-hz 2.2e9 --mode one-way -o pass.parquet

        cat sample_data/doppler_pass.csv \\
            | trackproc ingest - --stations sample_data/stations.csv --carrier-hz 2.2e9 --mode one-way \\
            | trackproc info -
    """
    from trackproc.io.validate import parse_duration

    max_gap = parse_duration(max_gap, "--max-gap")
    if inputs.count("-") > 1:
        raise typer.BadParameter("stdin (-) can be read only once", param_hint="INPUT")
    if sidecar is not None and len(inputs) > 1:
        raise typer.BadParameter("--sidecar applies to a single DopTrack input", param_hint="--sidecar")
    out = resolve_output(output, "output pass file")
    out_format = table_format_for(out, fmt)

    from trackproc.io.pass_stream import canonical_schema, write_pass_batches
    from trackproc.io.stations import read_stations
    from trackproc.io.tabular import iter_raw
    from trackproc.pipeline.ingest import Ingest, IngestOptions

    runs = [iter_raw(path, layout.value, sidecar=sidecar, carrier_hz=carrier_hz, drop_invalid=drop_invalid,
                     tdm_two_way_range=tdm_two_way_range.value) for path in inputs]   # lazy: opened when read
    table = {}
    if stations is not None:
        # SINEX positions are dated by the data: the first chunk of the first input (velocities of
        # cm/yr make the days of one ingest negligible), put back in front of its input
        head = next(runs[0], None)
        if head is not None:
            runs[0] = itertools.chain([head], runs[0])
        table = read_stations(stations, epoch=_epoch_of(head), eccentricities=eccentricities)
    options = IngestOptions(
        carrier_hz=carrier_hz, doppler_mode=mode.value if mode is not None else None, max_gap_s=max_gap,
        drop_invalid=drop_invalid, sigma_range_m=10.0 if sigma_range_m is None else sigma_range_m,
        sigma_range_explicit=sigma_range_m is not None, sigma_range_rate_m_s=sigma_range_rate_m_s,
        sigma_doppler_hz=sigma_doppler_hz, sigma_angle_deg=sigma_angle_deg)
    run = Ingest(table, options)
    for chunks in runs:   # streamed: a chunk of rows at a time (docs/ingest.md)
        run.add_input(chunks)
    result = run.finish()
    for warning in result.warnings:
        log.warning("%s", warning)
    if result.dropped:
        log.warning("dropped %d invalid samples: %s", sum(result.dropped.values()),
                    ", ".join(f"{reason} {n}" for reason, n in result.dropped.items()))
    schema = canonical_schema(result.meta)
    write_pass_batches(result.samples.arrow_batches(schema), schema, out, out_format.value)
    samples, passes, station_count = result.samples.counts()
    log.info("ingested %d samples, %d pass(es), %d station(s) -> %s (%s)", samples, passes, station_count,
             "stdout" if out == "-" else out, out_format.value)


def _epoch_of(raw):
    """The middle of a chunk's time span (UTC datetime64), to date SINEX station positions."""
    import numpy as np

    times = raw.frame["time"].dropna() if raw is not None and len(raw.frame) else None
    if times is None or not len(times):
        return None
    lo, hi = times.min(), times.max()
    return np.datetime64((lo + (hi - lo) / 2).tz_convert("UTC").tz_localize(None), "ns")
