"""The text summary of ``fit-tle`` (stderr / ``--summary``)."""

from __future__ import annotations

from typing import TYPE_CHECKING


if TYPE_CHECKING:
    from trackproc.pipeline.fit_tle import FitTleResult


def summary_text(result: FitTleResult) -> str:
    """The people's summary on stderr."""
    s = result.summary
    c = s["classical"]
    sig = s["sigma"]
    lines = [f"fit-tle: epoch {s['epoch']} ({s['initial_age_days']:+.2f} d from the initial), {s['samples']} samples, "
             f"{s['edited']} edited, {s['iterations']} iterations",
             f"  n {c['mean_motion_rev_day']:.8f} ± {sig['n_rev_per_day']:.2g} rev/day, e {c['eccentricity']:.7f}, "
             f"i {c['inclination_deg']:.4f} ± {sig['i_deg']:.2g} deg, RAAN {c['raan_deg']:.4f} ± "
             f"{sig['raan_deg']:.2g} deg, lambda ± {sig['lambda_deg']:.2g} deg, B* {c['bstar']:.4g} ± {sig['bstar']:.2g}"]
    shown = s["groups"] if len(s["groups"]) <= 12 else s["groups"][:10]
    for g in shown:
        unit = {"doppler": "Hz", "range_rate": "m/s", "range": "m", "azimuth": "rad", "elevation": "rad"}.get(
            g["kind"], "m")
        lines.append(f"  {g['group']}: RMS {g['rms']:.4g} {unit} (initial {g['rms_initial']:.4g}), "
                     f"{g['samples']} samples"
                     + (f", time shift against the initial orbit {g['time_shift_initial_s']:.3g} ± "
                        f"{g['time_shift_initial_sigma_s']:.2g} s" if "time_shift_initial_s" in g else ""))
    if len(shown) < len(s["groups"]):
        lines.append(f"  ... {len(s['groups']) - len(shown)} more passes and kinds (--json or --summary FILE)")
    if s.get("refused"):
        lines.append(f"  refused ({s['refused']['code']}): the initial orbit is written; the fit is in the summary "
                     "(refused.fitted_tle)")
    p = s.get("prediction")
    if p:
        lines.append(f"  predicted position error {p['span_days']:g} d on: {p['position_sigma_m']:.4g} m "
                     f"(initial {p['initial_position_sigma_m']:.4g} m; SGP4's theory error included)"
                     + (f"; the fit moves it {p['change_m']:.4g} m: better with probability "
                        f"{p['probability_better']:.3g}" if "probability_better" in p else ""))
    conflict = [r for r in result.quality.as_dict()["reasons"] if r["code"] == "apriori_conflict"]
    if conflict:                      # how close the data come to contradicting the initial orbit
        lines.append("  " + conflict[0]["message"].split(": ")[0])
    lines.append("  " + result.quality.text())
    return "\n".join(lines) + "\n"
