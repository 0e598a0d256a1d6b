"""Options shared by several commands, defined once (names are part of the CLI contract)."""

from __future__ import annotations

import sys
from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from trackproc import vocabulary


def choices(name: str, values) -> type[Enum]:
    """A ``str`` Enum of option values drawn from :mod:`trackproc.vocabulary` (typer's choices);
    member names are the values with ``-`` and ``+`` as ``_`` (``Force.two_body``)."""
    return Enum(name, [(v.replace("-", "_").replace("+", "_"), v) for v in values], type=str)


Force = choices("Force", vocabulary.FORCES)
Earth = choices("Earth", vocabulary.EARTHS)
RangeRateModel = choices("RangeRateModel", vocabulary.RANGE_RATE_MODELS)
DopplerMode = choices("DopplerMode", vocabulary.LINK_MODES)
Noise = choices("Noise", vocabulary.NOISE_MODELS)


class TableFormat(str, Enum):
    parquet = "parquet"
    arrow = "arrow"
    csv = "csv"


ForceOpt = typer.Option(Force.j2, "--force", help="Force model: two-body, j2 or full (gravity field, Sun, Moon, SRP, drag, relativity; see the force-model options).")
EarthOpt = typer.Option(Earth.wgs84, "--earth",
                        help="wgs84 ellipsoid, or sphere (R = 6371 km, linear sidereal time, as seed 004).")
EopOpt = typer.Option(None, "--eop", help="IERS EOP file (finals2000A / finals.all): UT1-UTC and polar motion.",
                      exists=False, dir_okay=False)
Dut1Opt = typer.Option(None, "--dut1", help="UT1-UTC in seconds, when no EOP file is given.")
RangeRateModelOpt = typer.Option(
    RangeRateModel.doppler, "--range-rate-model",
    help="doppler: derivative of the light-time range (default); instantaneous: Orekit's one-way RangeRate.")
#: ``--range-rate-model`` of the commands that read pass files (their metadata says which, by default).
PassRangeRateModelOpt = typer.Option(
    None, "--range-rate-model",
    help="doppler (derivative of the light-time range) or instantaneous (Orekit's RangeRate); "
         "default: the pass files' metadata, else doppler.")
# The corrections of range samples (estimate, filter): docs/slr.md.
TroposphereOpt = typer.Option(
    "auto", "--troposphere", metavar="auto|mendes-pavlis|none",
    help="Tropospheric delay of range samples: Mendes-Pavlis + FCULa from the CRD meteo records (auto: laser "
         "sessions not already corrected; mendes-pavlis: every range, needs a wavelength; none).")
ComOffsetOpt = typer.Option(0.0, "--com-offset", metavar="M",
                            help="Target centre-of-mass offset subtracted from modelled ranges, m (LAGEOS 0.251).")
WavelengthOpt = typer.Option(None, "--wavelength-nm", metavar="NM",
                             help="Laser wavelength for --troposphere mendes-pavlis on ranges without a CRD "
                                  "configuration record.")
SolidTidesOpt = typer.Option(
    None, "--solid-tides/--no-solid-tides", show_default=False,
    help="Solid-Earth tide displacement of the stations on range samples (IERS 2010 step 1; default: on for "
         "CRD laser data).")
EccentricitiesOpt = typer.Option(None, "--eccentricities", metavar="ECC.snx",
                                 help="SINEX eccentricities applied to --stations FILE.snx.")
#: The OPM's object (estimate, refine).
OpmObjectNameOpt = typer.Option("UNKNOWN", "--object-name", help="OBJECT_NAME of the OPM.")
OpmObjectIdOpt = typer.Option("UNKNOWN", "--object-id", help="OBJECT_ID of the OPM.")
StationsOpt = typer.Option(..., "--stations", help="Stations table CSV: station, lat_deg, lon_deg, height_m.")
OutputOpt = typer.Option(None, "-o", "--output",
                         help="Output file, or - for stdout (default: stdout when it is a pipe).")


def named_values(items: list, flag: str) -> dict:
    """``NAME=NUMBER`` options (``--apriori-sigma x=1000``) as a dict; a usage error otherwise."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            sep = ""
        if not sep or not name.strip():
            raise typer.BadParameter(f"expected NAME=SIGMA, got {item!r}", param_hint=flag)
        if name.strip() in out:
            raise typer.BadParameter(f"{name.strip()} given twice", param_hint=flag)
        out[name.strip()] = number
    return out


def resolve_output(output: Optional[str], what: str = "output") -> str:
    """``-o`` given: use it. Not given: stdout when it is not a terminal, else a usage error."""
    if output is not None:
        if output != "-":
            parent = Path(output).parent
            if str(parent) not in ("", ".") and not parent.exists():
                # a mistyped directory is not created silently (one under a file, or unwritable, is
                # the output guard's: it names the OS error)
                ancestor = next((a for a in parent.parents if a.exists()), None)
                if ancestor is None or ancestor.is_dir():
                    raise typer.BadParameter(f"directory {str(parent)!r} of {output!r} does not exist; "
                                             "expected an existing directory", param_hint="-o/--output")
        return output
    if not sys.stdout.isatty():
        return "-"
    raise typer.BadParameter(f"no {what} given: use -o FILE, or -o - / a pipe for stdout",
                             param_hint="-o/--output")


def table_format_for(output: str, requested: Optional[TableFormat]) -> TableFormat:
    """Format from ``--format``, else from the file suffix.

    On stdout: an Arrow stream into a pipe (a reader can consume it as it comes); when stdout
    is redirected to a regular file (``trackproc smooth - > out.parquet``) the format follows
    that file's suffix, and is Parquet when the suffix says nothing.
    """
    if output == "-" and sys.stdout.isatty() and requested is not TableFormat.csv:
        raise typer.BadParameter("stdout is a terminal: binary Parquet/Arrow is not written there; "
                                 "expected -o FILE, a pipe, or --format csv", param_hint="-o/--output")
    if requested is not None:
        return requested
    if output == "-":
        target = _stdout_file()
        if target is None:
            return TableFormat.arrow
        output = target
        if Path(output).suffix.lower() not in (".csv", ".arrow", ".arrows", ".ipc", ".feather"):
            return TableFormat.parquet
    suffix = Path(output).suffix.lower()
    if suffix == ".csv":
        return TableFormat.csv
    if suffix in (".arrow", ".arrows", ".ipc", ".feather"):
        return TableFormat.arrow
    if suffix not in ("", ".parquet", ".pq"):
        # ``-o x.txt`` would otherwise silently get Parquet bytes
        raise typer.BadParameter(f"cannot tell the table format from the suffix {suffix!r} of {output!r}; "
                                 "expected .parquet, .pq, .csv, .arrow, .arrows, .ipc or .feather, or --format",
                                 param_hint="-o/--output")
    return TableFormat.parquet


def _stdout_file() -> Optional[str]:
    """The path of the regular file stdout is redirected to, or None (pipe, terminal, unknown)."""
    import os
    import stat

    try:
        if not stat.S_ISREG(os.fstat(sys.stdout.fileno()).st_mode):
            return None
    except (OSError, ValueError, AttributeError):
        return None
    try:
        return os.readlink(f"/proc/self/fd/{sys.stdout.fileno()}")
    except OSError:
        return "stdout.parquet"  # a regular file of unknown name: Parquet


def summary(text: str) -> None:
    """A command's own result for people, on stderr: shown by default (unlike INFO lines), hidden by
    ``--quiet``."""
    import logging

    if logging.getLogger("trackproc").isEnabledFor(logging.WARNING):
        sys.stderr.write(text if text.endswith("\n") else text + "\n")
        sys.stderr.flush()


JsonSummaryOpt = typer.Option(False, "--json", help="The stderr summary as one JSON object (for scripts), not text.")
#: ``--strict`` of the commands with a quality verdict (README "Exit codes").
StrictOpt = typer.Option(False, "--strict",
                         help="Exit 1 when the quality verdict is 'suspect' too (a 'rejected' result always exits 1); "
                              "the outputs are written either way.")


def elements_line(state) -> str:
    """The state's osculating elements in one line, for the text summaries."""
    from trackproc.io.statefile import orbital_elements

    e = orbital_elements(state)
    angles = ", ".join(f"{name} {e[key]:.4f} deg" for name, key in (
        ("i", "i_deg"), ("RAAN", "raan_deg"), ("omega", "argp_deg"), ("M", "mean_anomaly_deg"),
        ("u", "arg_latitude_deg")) if e[key] is not None)
    return f"  elements (osculating, GCRF): a {e['a_m']:.1f} m, e {e['e']:.6f}, {angles}\n"


def summary_json(state, command: str, warnings=()) -> str:
    """The stderr summary of a state-producing command (refine, estimate) as one JSON line: the
    epoch, every parameter with its sigma, the osculating elements, the RTN sigmas, the quality
    verdict and the warnings."""
    import json

    import numpy as np

    from trackproc.io.jsonutil import json_ready
    from trackproc.io.statefile import format_epoch, orbital_elements

    sigma = state.sigma if state.sigma is not None else (
        np.sqrt(np.clip(np.diag(state.covariance), 0, None)) if state.covariance is not None else None)
    values = state.values if state.values is not None else state.rv
    params = {n: {"value": float(v), "sigma": None if sigma is None else float(s)}
              for n, v, s in zip(state.parameters, values, sigma if sigma is not None else [None] * len(values))}
    diag = state.diagnostics or {}
    doc = {"command": command, "epoch": format_epoch(state.epoch), "frame": "GCRF", "parameters": params,
           "elements": orbital_elements(state), "sigma_rtn": diag.get("sigma_rtn"),
           "converged": diag.get("converged"), "quality": state.extra.get("quality"), "warnings": list(warnings)}
    return json.dumps(json_ready(doc), allow_nan=False) + "\n"


OscillatorNoiseOpt = typer.Option(
    None, "--oscillator-noise", metavar="HZ_PER_SQRT_S",
    help="Random-walk intensity of the transmitter frequency (Hz/sqrt(s)) instead of estimating it.")


HorizonOpt = typer.Option(
    1.0, "--horizon", metavar="DAYS", min=0.0,
    help="Replace the initial orbit only when the solution predicts the position better with probability >= 0.9 "
         "somewhere over this many days; else keep it ('kept'). A stated a-priori (TLE, covariance, "
         "--apriori-sigma) the data contradict is kept ('declined'). See docs/design.md, 'Prior and decision'.")


def read_passes_and_stations(passes: list, stations: Optional[str], eccentricities: Optional[str] = None):
    """The pass files of ``estimate`` and ``filter`` (``-`` is stdin; each file once, no sample
    twice) and, with ``--stations``, the stations at the middle of their span (a SINEX file's
    positions move with time). Returns ``(tables [(source, PassTable)], stations or None)``."""
    from trackproc.io.atomic import is_stdio
    from trackproc.io.passfile import read_pass_table
    from trackproc.io.stations import read_stations
    from trackproc.io.validate import check_distinct_files, check_no_repeated_samples

    check_distinct_files(passes, "PASS")
    tables = [("<stdin>" if is_stdio(p) else p, read_pass_table(p)) for p in passes]
    if len(tables) > 1:        # one file's own repeats are its reader's business (and its DataFrame pandas's)
        check_no_repeated_samples([(source, t.frame) for source, t in tables])
    if stations is None:
        return tables, None
    import numpy as np

    times = np.concatenate([t.column("time") for _, t in tables])
    mid = times.min() + (times.max() - times.min()) // 2 if times.size else np.datetime64("NaT", "ns")
    return tables, read_stations(stations, epoch=mid, eccentricities=eccentricities)


def report_solution(result, command: str, as_json: bool, strict: bool, summary_text) -> None:
    """The end of ``refine`` and ``estimate``: the summary on stderr (``summary_text(result)``, or ``--json``; off
    under ``-q``), then the verdict's exit: ``rejected`` (or ``suspect`` with ``--strict``) exits 1
    with the outputs written, since they are complete and carry the verdict."""
    import logging

    log = logging.getLogger("trackproc")
    if log.isEnabledFor(logging.WARNING):   # the summary is the result for people: off only under -q
        sys.stderr.write(summary_json(result.state, command, result.warnings) if as_json
                         else summary_text(result) + elements_line(result.state))
        sys.stderr.flush()
    verdict = result.quality.verdict
    if verdict == "rejected" or (strict and verdict == "suspect"):
        log.error(f"{result.quality.text()}: the solution is written with its verdict; exit 1"
                  + (" (--strict)" if verdict == "suspect" else ""))
        from trackproc.io.atomic import commit_outputs

        commit_outputs()
        raise typer.Exit(1)
