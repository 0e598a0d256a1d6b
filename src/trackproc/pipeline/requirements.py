"""``trackproc requirements``: the sensor requirement g = σ sqrt(Δt) over a grid of orbits (seed 003).

For every cell (V, α, τ) of the grid: the unfavourable planar orbit of impact speed V and
angle α (App. A, φ = θ_f), the information distance ``‖Δε‖ = sqrt(∫ (ε₁ - ε₀)² dt)`` between
H0 (displacement 0) and H1 (displacement Δ*) over [t0, T - τ] (t0 = horizon rise under H0,
App. B, or the moving observer's rise), and ``g = ‖Δε‖ / γ`` (eq. 8), in rad·s^½. γ is given
(``--gamma``, default 5) or follows from the error probabilities: ``γ = Φ⁻¹(1-α) + Φ⁻¹(1-β)``
(α = β: ``α = 1 - Φ(γ/2)``). A cell whose visible flight ends before T - τ has no
observation window: ``g = 0`` (no sensor meets it), reported in ``empty_cells``.

The paper's Tables 2 and 3 are kept here (:data:`PAPER_TABLE2`, :data:`PAPER_TABLE3`) for the
side-by-side comparison (``compare_paper``).
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from typing import Optional

from trackproc.constants import MU_EARTH, OMEGA_EARTH
from trackproc.errors import InputError
from trackproc.methods import ballistic as bl
from trackproc.methods import detection as dt
from trackproc.methods.ballistic import R_PLANAR
from trackproc.pipeline.plotting import require_matplotlib  # noqa: F401  (re-exported for the CLI)

DEG = math.pi / 180.0
DEFAULT_VELOCITIES_KMS = (1.0, 2.0, 3.0, 4.0, 5.0)
DEFAULT_ANGLES_DEG = (12.0, 24.0, 36.0, 48.0, 60.0)
DEFAULT_TAUS_S = (20.0, 30.0, 50.0)
DEFAULT_DISPLACEMENT_M = 500.0
DEFAULT_GAMMA = 5.0
#: Fig. 3's curves: g = (1, 2, 3, 6, 9, 12, 15) 1e-3 rad s^½.
FIG3_G = (1e-3, 2e-3, 3e-3, 6e-3, 9e-3, 12e-3, 15e-3)
CSV_COLUMNS = ("velocity_kms", "angle_deg", "tau_s", "g")

#: Seed 003 Table 2: g·1e3 (Δ* = 500 m, stationary observer) [τ][α] -> values for V = 1..5 km/s.
PAPER_TABLE2 = {
    20: {12: (5.50, 2.76, 1.65, 1.08, 0.75), 24: (13.0, 5.50, 3.60, 2.66, 1.84), 36: (17.5, 8.00, 5.50, 4.70, 3.34),
         48: (21.5, 12.5, 8.00, 5.50, 4.60), 60: (27.0, 16.0, 9.50, 7.00, 6.00)},
    30: {12: (3.30, 1.90, 1.70, 1.10, 0.75), 24: (8.70, 5.50, 3.60, 2.70, 1.84), 36: (17.5, 8.00, 5.60, 3.70, 3.30),
         48: (21.5, 13.0, 8.00, 5.50, 4.60), 60: (27.0, 16.0, 9.50, 7.00, 5.80)},
    50: {12: (1.40, 1.90, 1.24, 0.85, 0.75), 24: (6.00, 4.16, 3.60, 2.16, 1.84), 36: (13.0, 8.00, 5.50, 3.70, 3.30),
         48: (21.5, 10.0, 8.00, 5.50, 4.60), 60: (27.0, 12.5, 9.50, 7.00, 6.00)},
}
#: Seed 003 Table 3: g·1e3 (Δ* = 500 m, latitude 60°, τ = 30 s) [direction][α] -> V = 1..5 km/s.
PAPER_TABLE3 = {
    "with": {12: (6.0, 4.0, 2.7, 1.5, 1.2), 24: (15, 7.0, 4.1, 3.2, 2.6), 36: (21, 11, 7.0, 5.2, 3.6),
             48: (34, 12, 8.6, 6.7, 5.5), 60: (37, 16, 11, 9.5, 6.3)},
    "against": {12: (2.1, 1.5, 1.1, 0.8, 0.4), 24: (6.7, 3.7, 2.6, 1.9, 1.3), 36: (14, 6.8, 4.3, 3.3, 2.4),
                48: (18, 9.6, 7.2, 4.7, 4.2), 60: (24, 11, 9.8, 6.3, 5.3)},
}
PAPER_VELOCITIES_KMS = (1, 2, 3, 4, 5)


@dataclass
class RequirementsOptions:
    """Grid and parameters of :func:`requirements` (units in the names)."""

    velocities_kms: tuple = DEFAULT_VELOCITIES_KMS
    angles_deg: tuple = DEFAULT_ANGLES_DEG
    taus_s: tuple = DEFAULT_TAUS_S
    displacement_m: float = DEFAULT_DISPLACEMENT_M
    gamma: Optional[float] = None
    alpha: Optional[float] = None
    beta: Optional[float] = None
    latitude_deg: Optional[float] = None
    direction: Optional[str] = None
    radius_m: Optional[float] = None


@dataclass
class Cell:
    """One grid cell: g (rad·s^½), ‖Δε‖ (rad·s^½), the conic, the visible window."""

    velocity_kms: float
    angle_deg: float
    tau_s: float
    g: float
    distance: float
    p_m: float
    e: float
    theta_f_deg: float
    rise_s_before_impact: float
    window_s: float
    paper_g: Optional[float] = None

    @property
    def ratio(self) -> Optional[float]:
        """paper / ours (None when either is missing or zero)."""
        if self.paper_g is None or self.g <= 0:
            return None
        return self.paper_g / self.g


@dataclass
class RequirementsResult:
    """Cells in grid order (τ, α, V), the γ used and its error probabilities, the options."""

    cells: list
    gamma: float
    alpha: float
    beta: float
    options: RequirementsOptions
    paper_table: Optional[str] = None
    empty_cells: list = field(default_factory=list)


def _check(options: RequirementsOptions) -> None:
    def positive_list(flag, values, hi=math.inf):
        if not values:
            raise InputError("empty list", column=flag, expected="at least one value")
        for v in values:
            if not (math.isfinite(v) and 0 < v < hi):
                raise InputError("out of range", column=flag, found=v, expected=f"numbers in (0, {hi:g})")

    positive_list("--velocity-kms", options.velocities_kms, 7.9)
    positive_list("--angle-deg", options.angles_deg, 90.0)
    positive_list("--tau-s", options.taus_s)
    if not (math.isfinite(options.displacement_m) and options.displacement_m != 0):
        raise InputError("invalid displacement", column="--displacement-m", found=options.displacement_m,
                         expected="a non-zero number of metres")
    if options.gamma is not None and (options.alpha is not None or options.beta is not None):
        raise InputError("give either --gamma or --alpha/--beta", column="--gamma", expected="one of them")
    if options.gamma is not None and not (math.isfinite(options.gamma) and options.gamma > 0):
        raise InputError("out of range", column="--gamma", found=options.gamma, expected="a number > 0")
    for flag, value in (("--alpha", options.alpha), ("--beta", options.beta)):
        if value is not None and not 0.0 < value < 0.5:
            raise InputError("out of range", column=flag, found=value, expected="a probability in (0, 0.5)")
    if options.latitude_deg is not None and not -90.0 <= options.latitude_deg <= 90.0:
        raise InputError("out of range", column="--latitude", found=options.latitude_deg,
                         expected="degrees in [-90, 90]")
    if options.direction is not None and options.direction not in ("with", "against"):
        raise InputError("unknown direction", column="--direction", found=options.direction,
                         expected="with or against")
    if (options.latitude_deg is None) != (options.direction is None):
        raise InputError("--latitude and --direction go together", column="--direction" if options.direction is None
                         else "--latitude", expected="both (moving observer, Table 3) or neither (Table 2)")
    if options.radius_m is not None and not 6.0e6 <= options.radius_m <= 7.0e6:
        raise InputError("out of range", column="--radius-m", found=options.radius_m,
                         expected="an Earth radius in metres in [6.0e6, 7.0e6]")


def resolve_gamma(options: RequirementsOptions) -> tuple[float, float, float]:
    """(γ, α, β): from ``gamma`` (α = β = 1 - Φ(γ/2)), or from α and β (one given: equal)."""
    if options.alpha is not None or options.beta is not None:
        alpha = options.alpha if options.alpha is not None else options.beta
        beta = options.beta if options.beta is not None else options.alpha
        return dt.gamma_from_errors(alpha, beta), alpha, beta
    gamma = options.gamma if options.gamma is not None else DEFAULT_GAMMA
    eq = dt.equal_error(gamma)
    return gamma, eq, eq


def paper_table_for(options: RequirementsOptions, gamma: float) -> Optional[str]:
    """``"table2"``/``"table3"`` when the options are the paper's (Δ* = 500 m, γ = 5, default R).

    Implements seed 003 Tables 2-3 (the published values).
    """
    if options.displacement_m != 500.0 or abs(gamma - 5.0) > 1e-9 or options.radius_m not in (None, 6371000.0):
        return None
    if options.latitude_deg is None:
        return "table2"
    if options.latitude_deg == 60.0:
        return "table3"
    return None


def _paper_value(table: Optional[str], options, v_kms, angle, tau) -> Optional[float]:
    if table is None or v_kms not in PAPER_VELOCITIES_KMS:
        return None
    col = PAPER_VELOCITIES_KMS.index(v_kms)
    if table == "table2":
        row = PAPER_TABLE2.get(tau, {}).get(angle)
    else:
        row = PAPER_TABLE3[options.direction].get(angle) if tau == 30 else None
    return None if row is None else row[col] * 1e-3


def cell(velocity_m_s: float, angle_rad: float, tau_s: float, displacement_m: float, gamma: float, *,
         latitude_rad: float | None = None, direction: str = "none", radius_m: float | None = None):
    """g (rad·s^½), ‖Δε‖ and the encounter of one cell (seed 003 eqs. 5-8 on eqs. 9-11)."""
    enc = bl.PlanarEncounter.from_impact(velocity_m_s, angle_rad, latitude_rad=latitude_rad, direction=direction,
                                         radius_m=radius_m or bl.R_PLANAR)
    rise = enc.rise_time()
    distance = dt.information_distance(lambda s: enc.elevation(s, displacement_m) - enc.elevation(s), rise, -tau_s)
    return dt.requirement_g(distance, gamma), distance, enc, rise


def requirements(options: RequirementsOptions) -> RequirementsResult:
    """g for every (τ, α, V) of the grid (τ outermost, then α, then V, as the paper's tables).

    Implements seed 003 eq. 8 over a grid (Tables 2-3).
    """
    _check(options)
    gamma, alpha, beta = resolve_gamma(options)
    table = paper_table_for(options, gamma)
    lat = None if options.latitude_deg is None else options.latitude_deg * DEG
    direction = options.direction or "none"
    cells, empty = [], []
    for tau in options.taus_s:
        for angle in options.angles_deg:
            for v in options.velocities_kms:
                try:
                    g, distance, enc, rise = cell(v * 1000.0, angle * DEG, tau, options.displacement_m, gamma,
                                                  latitude_rad=lat, direction=direction, radius_m=options.radius_m)
                except ValueError as exc:
                    raise InputError(f"V = {v:g} km/s, alpha = {angle:g} deg: {exc}", column="--velocity-kms") from None
                window = max(0.0, -rise - tau)
                c = Cell(velocity_kms=float(v), angle_deg=float(angle), tau_s=float(tau), g=g, distance=distance,
                         p_m=enc.p_m, e=enc.e, theta_f_deg=enc.theta_f / DEG, rise_s_before_impact=-rise,
                         window_s=window, paper_g=_paper_value(table, options, _int_or(v), _int_or(angle), _int_or(tau)))
                if window <= 0:
                    empty.append(c)
                cells.append(c)
    return RequirementsResult(cells=cells, gamma=gamma, alpha=alpha, beta=beta, options=options,
                              paper_table=table, empty_cells=empty)


def _int_or(x: float):
    return int(x) if float(x).is_integer() else x


# --------------------------------------------------------------------------- formats

def to_csv(result: RequirementsResult) -> str:
    """``velocity_kms, angle_deg, tau_s, g`` (g in rad·s^½), one row per cell."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for c in result.cells:
        writer.writerow([repr(c.velocity_kms), repr(c.angle_deg), repr(c.tau_s), repr(float(c.g))])
    return out.getvalue()


def parameters(result: RequirementsResult) -> dict:
    o = result.options
    return {
        "displacement_m": o.displacement_m, "gamma": result.gamma, "alpha": result.alpha, "beta": result.beta,
        "observer": "stationary" if o.latitude_deg is None else
        {"latitude_deg": o.latitude_deg, "direction": o.direction, "omega_e_rad_s": OMEGA_EARTH},
        "radius_m": o.radius_m or R_PLANAR, "mu_m3_s2": MU_EARTH,
        "window": "[horizon rise under H0, T - tau]",
        "orbit": "unfavourable (phi = theta_f), planar, seed 003 eqs. 9-11, App. A-B",
    }


def to_json(result: RequirementsResult, compare_paper: bool = False) -> str:
    """Parameters and one record per cell (g and distance in rad·s^½, the conic, the window)."""
    cells = []
    for c in result.cells:
        rec = {"velocity_kms": c.velocity_kms, "angle_deg": c.angle_deg, "tau_s": c.tau_s, "g": c.g,
               "information_distance": c.distance, "p_m": c.p_m, "e": c.e, "theta_f_deg": c.theta_f_deg,
               "rise_s_before_impact": c.rise_s_before_impact, "window_s": c.window_s}
        if compare_paper:
            rec["paper_g"] = c.paper_g
            rec["paper_over_ours"] = c.ratio
        cells.append(rec)
    doc = {"parameters": parameters(result),
           "units": {"g": "rad s^0.5", "information_distance": "rad s^0.5", "angles": "deg", "times": "s"},
           "cells": cells,
           "empty_cells": [{"velocity_kms": c.velocity_kms, "angle_deg": c.angle_deg, "tau_s": c.tau_s}
                           for c in result.empty_cells]}
    if compare_paper:
        doc["paper_table"] = result.paper_table
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def to_markdown(result: RequirementsResult, compare_paper: bool = False) -> str:
    """Tables in the paper's layout: rows (τ, α), columns V, values g·1e3 (rad·s^½).

    With ``compare_paper``: each cell ``ours / paper (paper/ours)`` where the paper has a value.
    """
    o = result.options
    velocities = list(dict.fromkeys(c.velocity_kms for c in result.cells))
    observer = ("stationary observer" if o.latitude_deg is None else
                f"observer at latitude {o.latitude_deg:g} deg, object moving {o.direction} it")
    title = (f"g(V, alpha) x 1e3, rad s^0.5: Delta* = {o.displacement_m:g} m, gamma = {result.gamma:.4g} "
             f"(alpha = {result.alpha:.3g}, beta = {result.beta:.3g}), {observer}")
    lines = [title, ""]
    if compare_paper and result.paper_table:
        lines += [f"Cells: ours / paper {result.paper_table.replace('table', 'Table ')} (paper / ours).", ""]
    header = "| tau, s | alpha, deg | " + " | ".join(f"V = {v:g} km/s" for v in velocities) + " |"
    lines += [header, "|" + "---|" * (2 + len(velocities))]
    by_key = {(c.tau_s, c.angle_deg, c.velocity_kms): c for c in result.cells}
    for tau in dict.fromkeys(c.tau_s for c in result.cells):
        for angle in dict.fromkeys(c.angle_deg for c in result.cells):
            cells = []
            for v in velocities:
                c = by_key[(tau, angle, v)]
                text = "—" if c.window_s <= 0 else f"{c.g * 1e3:.2f}"
                if compare_paper and c.paper_g is not None:
                    ratio = f"{c.ratio:.2f}" if c.ratio is not None else "—"
                    text += f" / {c.paper_g * 1e3:.2f} ({ratio})"
                cells.append(text)
            lines.append(f"| {tau:g} | {angle:g} | " + " | ".join(cells) + " |")
    if result.empty_cells:
        lines += ["", "— : the visible flight ends before T - tau (no observation window)."]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- Fig. 3
