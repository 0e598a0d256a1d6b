"""``trackproc info``: what a pass file holds."""

from __future__ import annotations

import typer

from trackproc.cli.app import app


@app.command("info")
def info_command(
    path: str = typer.Argument(..., metavar="FILE|-", help="Any file trackproc reads or writes (recognised by its "
                               "content): pass files raw or canonical, stations, ephemerides, states, TLEs, CCSDS, "
                               "ILRS CRD/CPF, SINEX, ICGEM, DopTrack, Orekit .aer, summaries, residuals; - for stdin."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of a text table."),
) -> None:
    """Summarise any file trackproc reads or writes, recognised by its content: a pass file
    (stations, passes with start, end, duration, samples per kind, max elevation); a raw input
    before ingest (CSV/Parquet/Arrow, DopTrack CSV, Orekit .aer, ILRS CRD, CCSDS TDM: samples
    per kind and station, span, the reader's own facts); an ephemeris or ILRS CPF (span, step,
    radius range); a state file, TLE or CCSDS OPM (epoch, frame, state, orbital elements,
    sigmas with units); a TLE catalogue; a CCSDS OEM; a stations table, SINEX or ICGEM field
    (.gfc, .gfc.gz); a DopTrack YAML sidecar; detect's nominal file; smooth and batch summaries,
    residual tables, requirements tables and pass schedules. Anything else is refused ("not a
    file trackproc knows"), with the list of kinds.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc info sample_data/multistation.parquet

        trackproc info sample_data/stale.json

        trackproc info sample_data/iss.tle --json

        trackproc ingest sample_data/elevation_pass.csv --stations sample_data/stations.csv -o - \\
            | trackproc info - --json
    """
    import json
    import sys

    from trackproc.io.atomic import read_input_bytes
    from trackproc.pipeline.info import format_mapping
    from trackproc.pipeline.info_files import describe

    summary, text = describe(read_input_bytes(path), path)
    if as_json:
        from trackproc.io.jsonutil import json_ready

        sys.stdout.write(json.dumps(json_ready(summary), indent=2) + "\n")
    else:
        sys.stdout.write(text if text is not None else format_mapping(summary))
