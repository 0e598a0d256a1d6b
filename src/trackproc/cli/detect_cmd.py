"""``trackproc detect``: likelihood-ratio test of a trajectory displacement from angle passes (seed 003)."""

from __future__ import annotations

import logging
from typing import Optional

import typer

from trackproc.cli.app import app
from trackproc.cli.common import Dut1Opt, EopOpt

log = logging.getLogger("trackproc")


@app.command("detect")
def detect_command(
    input: str = typer.Argument(..., metavar="PASS", help="Canonical pass file with elevations, or - for stdin."),
    nominal: str = typer.Option(..., "--nominal", metavar="NOMINAL.json",
                                help="Nominal trajectory: impact_time, velocity_kms + angle_deg (or p_m + e), ..."),
    displacement_m: Optional[float] = typer.Option(None, "--displacement-m", metavar="D",
                                                   help="Displacement Delta* of H1, m (default: the nominal's, 500)."),
    false_alarm: Optional[float] = typer.Option(None, "--false-alarm", metavar="P",
                                                help="Threshold for this false-alarm probability."),
    equal_error: bool = typer.Option(False, "--equal-error",
                                     help="Equal-error threshold S > C_n/2 (the default)."),
    sigma_rad: Optional[float] = typer.Option(None, "--sigma-rad", metavar="S",
                                              help="Measurement sigma, rad (default: the pass's sigma column)."),
    eop: Optional[str] = EopOpt,
    dut1: Optional[float] = Dut1Opt,
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png",
                                       help="Plot measured and displaced angles against the nominal, and S against "
                                            "its laws under H0 and H1 (needs matplotlib: pip install 'trackproc[plot]')."),
    as_json: bool = typer.Option(False, "--json", help="The stderr summary as one JSON object (for scripts), not text."),
    output: Optional[str] = typer.Option(None, "-o", "--output", help="RESULT.json, or - for stdout (default)."),
) -> None:
    """Decide between H0 (the nominal trajectory) and H1 (displaced by Delta*) from a measured
    elevation pass: statistic S (seed 003 eq. 2), its mean and variance under both hypotheses
    (eqs. 3-4), the threshold, the decision and the achieved gamma, alpha, beta, as JSON.

    The decision is data, not an error: the exit status is 0 for H0 and for H1.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc simulate --ballistic sample_data/nominal.json --stations sample_data/stations.csv \\
            --hypothesis h1 --step 1 --elevation-mask-deg 0 --seed 1 -o ballistic.parquet
        trackproc detect ballistic.parquet --nominal sample_data/nominal.json --false-alarm 0.001 -o result.json
    """
    if false_alarm is not None and equal_error:
        raise typer.BadParameter("give either --false-alarm or --equal-error", param_hint="--false-alarm")
    if false_alarm is not None and not 0.0 < false_alarm < 1.0:
        raise typer.BadParameter(f"expected a probability in (0, 1), got {false_alarm}", param_hint="--false-alarm")
    if sigma_rad is not None and not sigma_rad > 0:
        raise typer.BadParameter(f"expected a sigma > 0 rad, got {sigma_rad}", param_hint="--sigma-rad")
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    if plot is not None:
        from trackproc.pipeline.plotting import require_matplotlib

        require_matplotlib()
    if input == "-" and nominal == "-":
        raise typer.BadParameter("stdin (-) can be read only once", param_hint="--nominal")

    from trackproc.io.atomic import is_stdio, write_text
    from trackproc.io.eop import earth_orientation
    from trackproc.io.passfile import read_pass_table
    from trackproc.pipeline.detect import (
        DetectOptions,
        detect,
        read_nominal,
        result_json,
    )

    nom = read_nominal(nominal)
    orientation = None
    if nom.model == "3d":
        orientation, warning = earth_orientation(eop, dut1)
        if warning:
            log.warning(warning)
    table = read_pass_table(input)
    result = detect(table, nom, DetectOptions(displacement_m=displacement_m, false_alarm=false_alarm,
                                              sigma_rad=sigma_rad),
                    source="<stdin>" if is_stdio(input) else input, eop=orientation)
    doc = result.document
    write_text(output or "-", result_json(doc))
    if plot is not None:
        from trackproc.io.atomic import write_bytes
        from trackproc.report.plots import detect_png

        write_bytes(plot, detect_png(result.samples, doc))
    from trackproc.cli.common import summary

    if as_json:
        import json

        summary(json.dumps({k: doc[k] for k in ("station", "pass_id", "decision", "threshold", "gamma",
                                                 "false_alarm_probability", "miss_probability")}
                           | {"S": doc["statistic"]["S"]}))
    else:
        summary("%s %s: S = %.4g, threshold %.4g -> %s (gamma %.3g, alpha %.3g, beta %.3g)" % (
            doc["station"], doc["pass_id"], doc["statistic"]["S"], doc["threshold"], doc["decision"], doc["gamma"],
            doc["false_alarm_probability"], doc["miss_probability"]))
