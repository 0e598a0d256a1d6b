"""The one-screen text summary of ``trackproc refine`` for a person (:func:`summary_text`)."""

from __future__ import annotations

from trackproc.pipeline.numbers import value_sigma
from trackproc.pipeline.refine import RefineResult


def summary_text(result: RefineResult) -> str:
    """One screen for a person: the refined state ± sigma, RTN sigmas, constraints, observability."""
    st = result.state
    d = st.diagnostics
    m = st.extra["refinement"]
    sol = result.solution
    lines = [f"trackproc refine ({m['cost']}{', circular' if m['circular'] else ''}): converged in "
             f"{sol.iterations} iterations ({sol.message}); traverse epoch {d['traverse']['epoch']} "
             f"({m['station']}/{m['pass_id']}, {m['kind']}); a-priori: {m['apriori']}"]
    for name, value, sigma, unit in zip(st.parameters, st.values, st.sigma, d["units"]):
        lines.append(f"  {name:<28s}{value_sigma(value, sigma, unit, width=18)}")
    s = d["sigma_rtn"]
    lines.append(f"  sigma RTN: radial {s['radial_m']:.3g} m, along {s['along_m']:.3g} m, cross {s['cross_m']:.3g} m; "
                 f"{s['radial_m_s']:.3g}, {s['along_m_s']:.3g}, {s['cross_m_s']:.3g} m/s")
    rr = d["residual_rms"]
    lines.append(f"  residual RMS {rr['value']:.4g} {rr['unit']} ({rr['range_rate_m_s']:.4g} m/s), samples "
                 f"{d['samples']}, edited {d['edited']}, cost {d['cost']:.6g}, "
                 f"condition number {d['condition_number']:.3g}")
    c = d["constraints"]
    rel = ", ".join(f"{v:.2e}" for v in c["relative"])
    lines.append(f"  constraints (eq. 5{', imposed' if c['imposed'] else ', not imposed'}): relative [{rel}]; "
                 f"r_ka {c['r_ka_m']:.3f} ± {c['r_ka_sigma_m']:.3g} m, e {c['eccentricity']:.2e}")
    o = result.observability
    sv = ", ".join(f"{v:.3g}" for v in o.state_singular_values)
    lines.append(f"  observability (state singular values, units of {o.reference}): {sv}")
    for i in o.unobservable:
        lines.append(f"    not seen by the pass: {o.direction_text(i)} (posterior/reference sigma {o.gain[i]:.2f})")
    if o.correction_rtn:
        for part, c in o.correction_rtn.items():
            lines.append(f"    correction {part}: R/A/C {c['radial_m']:.4g}, {c['along_m']:.4g}, {c['cross_m']:.4g} m; "
                         f"{c['radial_m_s']:.3g}, {c['along_m_s']:.3g}, {c['cross_m_s']:.3g} m/s")
    stale = st.extra["at_stale_epoch"]
    r_text = ", ".join(f"{v:.3f}" for v in stale["position_m"])
    v_text = ", ".join(f"{v:.5f}" for v in stale["velocity_m_s"])
    lines.append(f"  at the stale epoch {stale['epoch']}: r = [{r_text}] m, v = [{v_text}] m/s")
    for w in result.warnings:
        lines.append(f"  warning: {w}")
    if result.quality is not None:
        lines.append(f"  {result.quality.text()}")
    return "\n".join(lines) + "\n"
