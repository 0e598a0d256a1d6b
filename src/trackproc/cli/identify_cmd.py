"""``trackproc identify``: rank catalogue TLEs by their fit to a pass."""

from __future__ import annotations

import logging
from typing import Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.common import Dut1Opt, EarthOpt, EopOpt, RangeRateModelOpt
from trackproc.cli.compare_cmd import Remove

log = logging.getLogger("trackproc")


@app.command("identify")
def identify_command(
    pass_file: str = typer.Argument(..., metavar="PASS", help="Pass file (Parquet, Arrow, CSV); - for stdin."),
    tles: str = typer.Option(..., "--tles", metavar="CATALOGUE.tle",
                             help="Candidate TLEs (2- or 3-line sets, one after another)."),
    remove: Remove = typer.Option(Remove.offset_drift, "--remove",
                                  help="Fitted per pass and kind before the fit is judged (the transmitter's "
                                       "frequency is unknown): none, offset, offset+drift."),
    earth=EarthOpt,
    range_rate_model=RangeRateModelOpt,
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    output: Optional[str] = typer.Option(None, "-o", "--output", help="JSON ranking (default: stdout)."),
    max_candidates: int = typer.Option(2000, "--max-candidates", metavar="N", min=1,
                                       help="Refuse a catalogue of more TLEs than this (each is an SGP4 run and a "
                                            "fit; raise it for a larger catalogue)."),
) -> None:
    """Which catalogue object is this pass? Every candidate TLE (SGP4) is fitted to the pass with
    its own offset and drift, ranked by residual sum of squares, with likelihood ratios against
    the best and a verdict: decisive (every runner-up below 1/100) or ambiguous (with the
    runners-up).

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc simulate --tle sample_data/iss.tle --stations sample_data/stations.csv --duration 21600 \\
            --kinds doppler --carrier-hz 145.8e6 -o iss.parquet
        trackproc identify iss.parquet --tles sample_data/catalogue.tle -o ranking.json

    Exit status: 0 (the verdict, decisive or ambiguous, is in the output); 2 bad options or input;
    1 when no candidate can be evaluated.
    """
    import json

    from trackproc.io.atomic import read_input_bytes, write_text
    from trackproc.io.eop import earth_orientation
    from trackproc.io.jsonutil import json_ready
    from trackproc.io.passfile import read_pass_table
    from trackproc.pipeline.identify import identify, parse_catalogue

    if pass_file == "-" and tles == "-":
        raise typer.BadParameter("only one input can come from stdin", param_hint="--tles")
    orientation, warning = earth_orientation(eop, dut1)
    if warning:
        log.warning(warning)
    table = read_pass_table(pass_file)
    catalogue = parse_catalogue(read_input_bytes(tles).decode("utf-8", errors="replace"),
                                "<stdin>" if tles == "-" else tles)
    if len(catalogue) > max_candidates:
        raise typer.BadParameter(f"{tles}: {len(catalogue)} TLEs in the catalogue, more than {max_candidates} "
                                 "(each is an SGP4 run and a fit against the pass); raise --max-candidates to "
                                 "evaluate them all", param_hint="--max-candidates")
    result = identify(table, catalogue, orientation, remove=remove.value, range_rate_model=range_rate_model.value,
                      earth=earth.value)
    write_text(output or "-", json.dumps(json_ready(result), indent=2) + "\n")
    best = result["best"]
    others = ", ".join(f"{r['satnum']} (LR {r['likelihood_ratio']:.3g})" for r in result["runners_up"])
    log.info("%s: best %s%s of %d candidates%s", result["verdict"], best["satnum"],
             f" ({best['name']})" if best["name"] else "", len(catalogue),
             f"; runners-up {others}" if others else "")


__all__ = ["identify_command"]
