"""``trackproc info``: what a pass file holds."""

from __future__ import annotations

import typer

from trackproc.cli.app import app


@app.command("info")
def info_command(
    path: str = typer.Argument(..., metavar="FILE|-", help="Pass file or ephemeris (Parquet, Arrow, CSV) or - for stdin."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of a text table."),
) -> None:
    """Summarise a pass file: stations, passes (start, end, duration, samples per kind), max elevation;
    or an ephemeris from `trackproc propagate`: span, step, radius and altitude range.

    Example:

        trackproc info pass.parquet

        trackproc ingest raw.csv --stations stations.csv -o - | trackproc info - --json
    """
    import json
    import sys

    from trackproc.errors import InputError
    from trackproc.io.atomic import read_input_bytes
    from trackproc.io.passfile import parse_pass_table
    from trackproc.pipeline.info import ephemeris_info, format_info, info_dict, summarize

    source = "<stdin>" if path == "-" else path
    data = read_input_bytes(path)
    if data.lstrip().startswith(b"CCSDS_OEM_VERS"):
        raise InputError("a CCSDS OEM is an exchange output", file=source, row=1,
                         expected="a pass file or an ephemeris in Parquet, Arrow or CSV "
                                  "(trackproc propagate without --format oem)")
    if data.lstrip()[:1] in (b"{", b"["):
        raise InputError("a JSON document (a state or nominal file?) is not a pass file", file=source, row=1,
                         expected="a pass file or an ephemeris in Parquet, Arrow or CSV (info reads those)")
    if data.lstrip().startswith(b"CCSDS_TDM_VERS"):
        raise InputError("a raw CCSDS TDM is not a pass file", file=source, row=1,
                         expected="a pass file: run trackproc ingest on it first")
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
