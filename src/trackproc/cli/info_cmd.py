"""``trackproc info``: what a pass file holds."""

from __future__ import annotations

import typer

from trackproc.cli.app import app


@app.command("info")
def info_command(
    path: str = typer.Argument(..., metavar="FILE|-", help="Any file trackproc reads or writes: pass file or "
                               "ephemeris (Parquet, Arrow, CSV), state JSON, TLE, CCSDS OPM, OEM or TDM; - for stdin."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of a text table."),
) -> None:
    """Summarise any file trackproc handles: a pass file (stations, passes with start, end, duration,
    samples per kind, max elevation); an ephemeris (span, step, radius and altitude range); a state
    file, TLE or CCSDS OPM (epoch, frame, state, orbital elements, sigmas); a CCSDS OEM (object,
    frame, span, states) or TDM (samples per station and kind, span).

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc info sample_data/multistation.parquet

        trackproc info sample_data/stale.json

        trackproc info sample_data/iss.tle --json

        trackproc ingest sample_data/elevation_pass.csv --stations sample_data/stations.csv -o - \\
            | trackproc info - --json
    """
    import json
    import sys

    from trackproc.errors import InputError
    from trackproc.io.atomic import read_input_bytes
    from trackproc.io.passfile import parse_pass_table
    from trackproc.pipeline.info import (ephemeris_info, file_kind, format_info, format_mapping, info_dict,
                                         oem_info, opm_info, state_info, summarize, tdm_info, tle_info)

    source = "<stdin>" if path == "-" else path
    data = read_input_bytes(path)
    kind = file_kind(data)
    if kind != "table":
        summary = {"state": state_info, "tle": tle_info, "opm": opm_info, "oem": oem_info,
                   "tdm": tdm_info}[kind](data, source)
        sys.stdout.write(json.dumps(summary, indent=2) + "\n" if as_json else format_mapping(summary))
        return
    try:
        table = parse_pass_table(data, source)
    except InputError as not_a_pass_file:
        # an ephemeris from `trackproc propagate` gets its own summary
        from trackproc.io.ephemeris import parse_ephemeris

        try:
            eph = parse_ephemeris(data, source)
        except InputError:
            raise not_a_pass_file from None
        summary = ephemeris_info(eph.frame, eph.meta, source)
        text = json.dumps(summary, indent=2) + "\n" if as_json else "".join(
            f"{k:<28}{v}\n" for k, v in summary.items())
        sys.stdout.write(text)
        return
    info = summarize(table, source)
    text = json.dumps(info_dict(info), indent=2) + "\n" if as_json else format_info(info)
    sys.stdout.write(text)
