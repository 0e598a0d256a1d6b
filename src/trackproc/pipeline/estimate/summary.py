"""The one-screen text summary of an estimate (:func:`summary_text`)."""

from __future__ import annotations

import math

import numpy as np

from trackproc.isotime import iso_utc
from trackproc.pipeline.numbers import value_sigma
from trackproc.pipeline.estimate.result import EstimateResult


def _for_people(value, unit) -> str:
    """A value with its unit as a person reads it: angles in degrees (radians stay in the files)."""
    if unit == "rad":
        return f"{math.degrees(value):.4g} deg"
    return f"{value:.4g} {unit}"


def _fmt(value, sigma, unit):
    if unit == "rad":     # angle biases: degrees for people
        value, sigma, unit = math.degrees(value), math.degrees(sigma), "deg"
    return value_sigma(value, sigma, unit, width=18)


def summary_text(result: EstimateResult) -> str:
    """One screen for a person: parameters ± sigma, RTN sigmas, fit statistics, RMS per station."""
    sol = result.solution
    st = result.state
    d = st.diagnostics
    units = d["units"]
    lines = [f"trackproc estimate: {'converged' if sol.converged else 'NOT converged'} in {sol.iterations} "
             f"iterations ({sol.message}); epoch {iso_utc(st.epoch, 3)}, GCRF, "
             f"force {st.force_model}, range-rate model {result.problem.range_rate_model}"]
    for name, value, sigma, unit in zip(sol.names, sol.values, sol.sigma, units):
        lines.append(f"  {name:<28s}{_fmt(value, sigma, unit)}")
    s = d["sigma_rtn"]
    lines.append(f"  sigma RTN: radial {s['radial_m']:.3g} m, along {s['along_m']:.3g} m, cross {s['cross_m']:.3g} m; "
                 f"{s['radial_m_s']:.3g}, {s['along_m_s']:.3g}, {s['cross_m_s']:.3g} m/s")
    lines.append(f"  samples {sol.n_measurements}, edited {sol.n_edited}, dof {sol.dof}, chi2 {sol.chi2:.6g}, "
                 f"variance factor {sol.variance_factor:.4g}, condition number {sol.condition_number:.3g}")
    for station, kinds in d["rms"].items():
        parts = [f"{k} {_for_people(v['rms'], v['unit'])} (n {v['n']}, edited {v['edited']}, wrms {v['wrms']:.3g})"
                 for k, v in kinds.items() if v["rms"] is not None]
        lines.append(f"  {station}: " + "; ".join(parts))
    if result.comparison and "doppler_only_sigma" in result.comparison:
        c = result.comparison
        lines.append("  seed 002 comparison (sigma): parameter, without ranges, extended")
        for n, a, b in zip(c["parameters"], c["doppler_only_sigma"], c["extended_sigma"]):
            lines.append(f"    {n:<28s}{a:>14.5g}{b:>14.5g}")
    elif result.comparison:
        lines.append(f"  seed 002 comparison: {result.comparison.get('doppler_only')}")
    if result.two_stage is not None:
        two = result.two_stage
        lines.append(f"  two-stage (seed 002 eqs. 17-22): |K' - (K - dK)|/|K| = {two.identity_error:.2g}, "
                     f"min eig dK = {two.delta_k_min_eigenvalue:.3g}")
        for n, a, b in zip(two.names, np.sqrt(np.diag(two.k)), np.sqrt(np.diag(two.k_prime))):
            lines.append(f"    {n:<28s} sigma K {a:>12.5g}  sigma K' {b:>12.5g}")
        for sname, b, p in zip(two.stations, two.biases, np.sqrt(np.diag(two.pi))):
            lines.append(f"    stage-1 range_bias:{sname} = {b:.3f} ± {p:.3g} m")
    for w in result.warnings:
        lines.append(f"  warning: {w}")
    if result.quality is not None:
        lines.append(f"  {result.quality.text()}")
    return "\n".join(lines) + "\n"
