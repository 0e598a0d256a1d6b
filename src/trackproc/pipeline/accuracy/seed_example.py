"""The seed 000 worked example (eqs. 29-34) with its truncation study (:func:`seed_example`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd

from trackproc import __version__
from trackproc.constants import MU_EARTH
from trackproc.errors import InputError
from trackproc.methods import accuracy as ac
from trackproc.pipeline.accuracy.options import MAX_TIMES


@dataclass
class SeedExampleOptions:
    """Seed 000's worked example: one axis of a circular orbit of radius ``radius_m``."""

    span_s: float = 6000.0
    step_s: float = 100.0
    radius_m: float = 7.0e6
    sigma_position_m: float = 100.0
    sigma_velocity_m_s: float = 0.1
    discretes: tuple = (4, 6)
    mu_m3_s2: float = MU_EARTH


@dataclass
class SeedExampleResult:
    frame: pd.DataFrame
    meta: dict
    options: SeedExampleOptions
    n_rad_s: float


def seed_example(options: SeedExampleOptions) -> SeedExampleResult:
    """The seed's worked example (seed 000 eqs. 29-34): sigma_x(t) exactly, by the spectral
    method with enough discretes, and truncated at ``discretes`` (4 and 6 in the paper).

    Columns: ``elapsed_s``, ``mean_x_m`` (eq. 18, the nominal x0 cos(nt)), ``sigma_x_m`` and
    ``sigma_vx_m_s`` (exact), ``sigma_x_spectral_m``, ``sigma_vx_spectral_m_s`` and
    ``rel_err_var_x_spectral`` (enough discretes, restarted expansion), ``sigma_x_n{N}_m`` and
    ``rel_err_var_x_n{N}`` (single expansion H = t with N discretes, the paper's method),
    ``velocity_share`` (fraction of D_x due to the velocity error) and ``velocity_weight_s2``
    (``tan^2(nt)/n^2``, the seed's conclusion).
    """
    o = options
    for flag, value in (("--span", o.span_s), ("--step", o.step_s), ("--radius-m", o.radius_m)):
        if not (math.isfinite(value) and value > 0):
            raise InputError("must be positive", column=flag, found=value, expected="a number > 0")
    if o.span_s / o.step_s > MAX_TIMES:
        raise InputError("too many times", column="--step", found=o.step_s, expected=f"at most {MAX_TIMES} steps")
    for flag, value in (("--sigma-position-m", o.sigma_position_m), ("--sigma-velocity-m-s", o.sigma_velocity_m_s)):
        if not (math.isfinite(value) and value >= 0):
            raise InputError("invalid sigma", column=flag, found=value, expected="a number >= 0")
    if o.sigma_position_m == 0 and o.sigma_velocity_m_s == 0:
        raise InputError("both sigmas are zero", column="--sigma-position-m", expected="at least one positive sigma")
    bad = [d for d in o.discretes if not (isinstance(d, int) and 1 <= d <= 200)]
    if bad or not o.discretes:
        raise InputError("invalid number of discretes", column="--discretes", found=bad or "none",
                         expected="integers in [1, 200], e.g. 4,6")
    n = math.sqrt(o.mu_m3_s2 / o.radius_m ** 3)
    t = np.arange(int(math.floor(o.span_s / o.step_s * (1 + 1e-12))) + 1) * float(o.step_s)
    s1, s2 = float(o.sigma_position_m), float(o.sigma_velocity_m_s)
    exact = ac.seed000_variance_exact(t, s1, s2, n)
    exact_v = ac.seed000_velocity_variance_exact(t, s1, s2, n)
    spectral = ac.seed000_statistics(t, s1, s2, n, x0_m=o.radius_m)
    cols = {"elapsed_s": t, "mean_x_m": spectral["mean_x_m"], "sigma_x_m": np.sqrt(exact),
            "sigma_vx_m_s": np.sqrt(exact_v), "sigma_x_spectral_m": spectral["sigma_x_m"],
            "sigma_vx_spectral_m_s": spectral["sigma_vx_m_s"],
            "rel_err_var_x_spectral": _rel(spectral["var_x_m2"], exact)}
    for nd in o.discretes:
        st = ac.seed000_statistics(t, s1, s2, n, n_discretes=nd, x0_m=o.radius_m)
        cols[f"sigma_x_n{nd}_m"] = st["sigma_x_m"]
        cols[f"rel_err_var_x_n{nd}"] = _rel(st["var_x_m2"], exact)
    vel = s2 ** 2 * np.sin(n * t) ** 2 / n ** 2
    cols["velocity_share"] = np.divide(vel, exact, out=np.zeros_like(vel), where=exact > 0)
    with np.errstate(over="ignore"):
        cols["velocity_weight_s2"] = ac.seed000_velocity_weight(t, n)
    meta = {"schema_version": 1, "product": "trackproc accuracy --seed-example",
            "model": "seed 000 eqs. 29-31: x'' = -(mu/r^3) x, x(0) = x0 - v1, x'(0) = g0 - v2, "
                     "independent zero-mean v1 (position), v2 (velocity); x0 = r, g0 = 0",
            "ground_truth": "D_x(t) = s1^2 cos^2(n t) + s2^2 sin^2(n t)/n^2 (the printed eqs. 33-34 have typos)",
            "radius_m": o.radius_m, "mu_m3_s2": o.mu_m3_s2, "n_rad_s": n, "period_s": 2 * math.pi / n,
            "sigma_position_m": s1, "sigma_velocity_m_s": s2, "discretes": list(o.discretes),
            "spectral": {"discretes": spectral["n_discretes"], "restart_s": 0.5 / n,
                         "note": "expansion restarted every 0.5/n s (|n H| <= 0.5), as the DT engine steps"},
            "truncated": "single expansion about t = 0 with H = t and N discretes (the paper's method); "
                         "complete Cauchy products, so N = 4 reproduces eq. 33 (typos corrected)",
            "span_s": o.span_s, "step_s": o.step_s, "trackproc_version": __version__}
    return SeedExampleResult(frame=pd.DataFrame(cols), meta=meta, options=o, n_rad_s=n)


def _rel(value, exact):
    return np.divide(value - exact, exact, out=np.zeros_like(exact), where=exact > 0)


def truncation_table(result: SeedExampleResult, times_s: Sequence[float]) -> pd.DataFrame:
    """Rows of the example frame at ``times_s`` (nearest grid times): the README's table."""
    f = result.frame
    idx = [int(np.argmin(np.abs(f["elapsed_s"].to_numpy() - x))) for x in times_s]
    cols = ["elapsed_s", "sigma_x_m"] + [c for c in f.columns if c.startswith("rel_err_var_x")]
    return f.iloc[idx][cols].reset_index(drop=True)
