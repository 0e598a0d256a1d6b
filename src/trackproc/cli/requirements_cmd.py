"""``trackproc requirements``: the angle sensor's g = σ sqrt(Δt) for detecting an orbit displacement (seed 003)."""

from __future__ import annotations

import logging
from enum import Enum
from typing import List, Optional

import typer

from trackproc.cli.app import app

log = logging.getLogger("trackproc")


class OutFormat(str, Enum):
    csv = "csv"
    json = "json"
    md = "md"


class Direction(str, Enum):
    with_ = "with"
    against = "against"


def _numbers(values: Optional[List[str]], flag: str) -> Optional[tuple]:
    """Comma lists and repeated options -> tuple of floats (None when not given)."""
    if not values:
        return None
    out = []
    for item in values:
        for text in item.split(","):
            if not text.strip():
                continue
            try:
                out.append(float(text))
            except ValueError:
                raise typer.BadParameter(f"expected numbers, got {text.strip()!r}", param_hint=flag) from None
    return tuple(out)


@app.command("requirements")
def requirements_command(
    velocity_kms: Optional[List[str]] = typer.Option(None, "--velocity-kms", metavar="V[,V...]",
                                                     help="Impact speeds, km/s (default 1,2,3,4,5)."),
    angle_deg: Optional[List[str]] = typer.Option(None, "--angle-deg", metavar="A[,A...]",
                                                  help="Impact angles below the horizontal, deg (default 12,24,36,48,60)."),
    tau_s: Optional[List[str]] = typer.Option(None, "--tau-s", metavar="T[,T...]",
                                              help="Reaction times: observation stops tau s before impact (default 20,30,50)."),
    displacement_m: float = typer.Option(500.0, "--displacement-m", metavar="D",
                                         help="Displacement Delta* to detect, m."),
    gamma: Optional[float] = typer.Option(None, "--gamma", help="Discrimination gamma (default 5: alpha = beta = 0.0062)."),
    alpha: Optional[float] = typer.Option(None, "--alpha", help="False-alarm probability (instead of --gamma)."),
    beta: Optional[float] = typer.Option(None, "--beta", help="Miss probability (default: equal to --alpha)."),
    latitude: Optional[float] = typer.Option(None, "--latitude", "--latitude-deg", metavar="DEG",
                                             help="Observer latitude, deg: in-plane motion omega_E cos(lat) (Table 3)."),
    direction: Optional[Direction] = typer.Option(None, "--direction",
                                                  help="Object moving with or against the observer (with --latitude)."),
    radius_m: Optional[float] = typer.Option(None, "--radius-m", help="Earth radius of the planar model, m (6371000)."),
    fmt: OutFormat = typer.Option(OutFormat.csv, "--format", help="csv (velocity_kms, angle_deg, tau_s, g), json or md."),
    compare_paper: bool = typer.Option(False, "--compare-paper",
                                       help="json/md: add the paper's Table 2/3 value and the ratio to each cell."),
    plot: Optional[str] = typer.Option(None, "--plot", metavar="FILE.png",
                                       help="Plot dt = (g/sigma)^2 against sigma (Fig. 3); needs matplotlib."),
    output: Optional[str] = typer.Option(None, "-o", "--output", help="Output file, or - for stdout (default)."),
) -> None:
    """Sensor requirement g = sigma sqrt(dt) = ||d eps|| / gamma (seed 003 eq. 8, rad s^0.5) for
    unfavourable planar orbits over a grid of impact speed V, angle alpha and reaction time tau.

    A sensor with noise sigma (rad) and sample spacing dt (s) detects the displacement with the
    chosen error probabilities when sigma sqrt(dt) <= g, i.e. dt <= (g/sigma)^2.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc requirements --format md --compare-paper

        trackproc requirements --velocity-kms 3 --angle-deg 48 --tau-s 30 --alpha 0.001 --beta 0.01

        trackproc requirements --latitude 60 --direction against --tau-s 30 -o table3_against.csv
    """
    if plot == "-":
        raise typer.BadParameter("the plot cannot go to stdout; give a file name", param_hint="--plot")
    if gamma is not None and (alpha is not None or beta is not None):
        raise typer.BadParameter("give either --gamma or --alpha/--beta", param_hint="--gamma")
    if compare_paper and fmt == OutFormat.csv:
        raise typer.BadParameter("the CSV columns are fixed; use --format json or md", param_hint="--compare-paper")

    from trackproc.io.atomic import write_bytes, write_text
    from trackproc.pipeline import requirements as rq

    if plot is not None:
        rq.require_matplotlib()
    options = rq.RequirementsOptions(
        velocities_kms=_numbers(velocity_kms, "--velocity-kms") or rq.DEFAULT_VELOCITIES_KMS,
        angles_deg=_numbers(angle_deg, "--angle-deg") or rq.DEFAULT_ANGLES_DEG,
        taus_s=_numbers(tau_s, "--tau-s") or rq.DEFAULT_TAUS_S,
        displacement_m=displacement_m, gamma=gamma, alpha=alpha, beta=beta, latitude_deg=latitude,
        direction=None if direction is None else direction.value, radius_m=radius_m)
    result = rq.requirements(options)
    for c in result.empty_cells:
        log.warning("V = %g km/s, alpha = %g deg, tau = %g s: the visible flight (%.1f s) ends before T - tau; g = 0",
                    c.velocity_kms, c.angle_deg, c.tau_s, c.rise_s_before_impact)
    if fmt == OutFormat.csv:
        text = rq.to_csv(result)
    elif fmt == OutFormat.json:
        text = rq.to_json(result, compare_paper)
    else:
        text = rq.to_markdown(result, compare_paper)
    png = None
    if plot is not None:
        from trackproc.report.requirements_plots import plot_bytes

        png = plot_bytes(result)
    write_text(output or "-", text)
    if png is not None:
        write_bytes(plot, png)
