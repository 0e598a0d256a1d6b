"""``trackproc import-orekit``: an Orekit orbit-determination configuration (``.in``) as the files
trackproc takes (stations table, initial state, defaults)."""

from __future__ import annotations

import logging

import typer

from trackproc.cli.app import app

log = logging.getLogger("trackproc")

#: The files written into the output directory.
STATIONS, INITIAL, DEFAULTS = "stations.csv", "initial.json", "defaults.toml"


@app.command("import-orekit")
def import_orekit_command(
    config: str = typer.Argument(..., metavar="FILE.in", help="Orekit orbit-determination configuration (key = value)."),
    output: str = typer.Option(..., "-o", "--output", metavar="DIR",
                               help=f"Directory to write {STATIONS}, {INITIAL} and {DEFAULTS} into (created)."),
) -> None:
    """Turn an Orekit orbit-determination configuration (the .in files of Orekit's
    OrbitDetermination tutorial and tests) into trackproc's inputs: DIR/stations.csv (the ground
    stations, WGS-84 geodetic, with range_bias_m = the station's range bias + the onboard range
    bias), DIR/initial.json (the initial orbit at orbit.date, UTC, in inertial.frame, with the
    spacecraft mass and, where the file switches drag or radiation pressure on, their areas and
    coefficients) and DIR/defaults.toml (the sigmas as ingest's --sigma-range-m/--sigma-angle-deg,
    the estimated biases as estimate's --range-bias/--angle-bias, the centre-of-mass offset as
    --com-offset; use it with TRACKPROC_CONFIG=DIR/defaults.toml). Keys the import does not carry
    are listed on stderr with what to use instead.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc import-orekit sample_data/orekit_od.in -o imported/
        TRACKPROC_CONFIG=imported/defaults.toml trackproc estimate sample_data/multistation.parquet \\
            --initial imported/initial.json -o solution.json

    docs/slr.md and docs/estimate.md run Orekit's own LAGEOS-2 and W3B files the same way.

    Exit status: 0 ok; 2 bad input (a line that is not key = value, a missing or non-numeric key,
    an orbit not in Cartesian form, stations on another ellipsoid).
    """
    import json
    import math
    import sys
    from pathlib import Path

    from trackproc.errors import InputError
    from trackproc.io import orekit_config as oc
    from trackproc.io.atomic import write_text
    from trackproc.io.jsonutil import json_ready

    if output == "-":
        raise typer.BadParameter("three files are written: give a directory", param_hint="-o")
    cfg = oc.read_orekit_config(config)
    rows = oc.stations(cfg)
    state = oc.initial_state(cfg)
    defaults = oc.options(cfg, rows)
    target = Path(output)
    if target.exists() and not target.is_dir():
        raise InputError("not a directory", file=output, column="-o", expected="a directory (created when absent)")
    target.mkdir(parents=True, exist_ok=True)

    columns = ["station", "lat_deg", "lon_deg", "height_m", "range_bias_m"]
    lines = [",".join(columns)]
    for r in rows:
        lines.append(",".join([r["station"]] + [repr(float(r[c])) for c in columns[1:]]))
    toml = [f"# trackproc defaults from {cfg.source} (TRACKPROC_CONFIG={target / DEFAULTS})"]
    if oc.crd_measurements(cfg):
        toml.append("# no [ingest] sigma_range_m: the CRD normal points' own precision is the range sigma")
    for section, values in defaults.items():
        toml.append(f"\n[{section}]")
        for key, value in values.items():
            toml.append(f"{key} = {'true' if value is True else repr(float(value))}")
    write_text(target / STATIONS, "\n".join(lines) + "\n")
    write_text(target / INITIAL, json.dumps(json_ready(state), indent=2) + "\n")
    write_text(target / DEFAULTS, "\n".join(toml) + "\n")
    for note in oc.not_carried(cfg):
        log.warning("not imported: %s", note)
    sigma = sorted({r["range_sigma_m"] for r in rows if math.isfinite(r["range_sigma_m"])})
    sys.stderr.write(f"{len(rows)} stations ({', '.join(r['station'] for r in rows)}), initial state "
                     f"{state['epoch']} {state['frame']}, range sigma {'/'.join(f'{s:g}' for s in sigma) or '-'} m "
                     f"-> {target}/{{{STATIONS}, {INITIAL}, {DEFAULTS}}}\n")


__all__ = ["import_orekit_command"]
