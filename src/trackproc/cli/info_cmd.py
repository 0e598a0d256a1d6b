"""``trackproc info``: what a pass file holds."""

from __future__ import annotations

import typer

from trackproc.cli.app import app


@app.command("info")
def info_command(
    path: str = typer.Argument(..., metavar="FILE|-", help="Pass file (Parquet, Arrow, CSV) or - for stdin."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of a text table."),
) -> None:
    """Summarise a pass file: stations, passes (start, end, duration, samples per kind), max elevation.

    Example:

        trackproc info pass.parquet

        trackproc ingest raw.csv --stations stations.csv -o - | trackproc info - --json
    """
    import json
    import sys

    from trackproc.io.passfile import read_pass_table
    from trackproc.pipeline.info import format_info, info_dict, summarize

    source = "<stdin>" if path == "-" else path
    info = summarize(read_pass_table(path), source)
    text = json.dumps(info_dict(info), indent=2) + "\n" if as_json else format_info(info)
    sys.stdout.write(text)
