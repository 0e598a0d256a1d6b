"""Validation on real data: the 44 DopTrack Delfi-C3 passes (../shared/realdata/doptrack-delfic3).

Each pass is ingested by the ingest pipeline and smoothed with the defaults of ``trackproc smooth``;
the TCA and carrier at closest approach are compared with the upstream team's own estimates in
each pass's YAML (``tracking.tca``/``tca_error``, ``tracking.fca``/``fca_error``). Upstream fits a
tanh plus a Fourier/polynomial residual function and takes the TCA at the zero of its second
derivative and fca there (DopTrack ``doptools.extraction.estimate_tca``), the same definition as
ours; the stated errors (median 0.03 s, 0.4 Hz) are the formal errors of that model.

What is physically defensible to assert, and is asserted:

- every pass is fitted to the level of the 2 Hz frequency quantisation (RMS 1-3 Hz);
- pass 202004011959 is reported as bad: the closest approach lies inside a 401.5 s gap that
  covers two thirds of the pass, so no TCA is claimed and the pass is "suspect";
- where the TCA is observed, the median difference from upstream is below 1 s and 20 Hz, and it
  is of the size of our sigma combined with the degree spread (model error), not of the
  upstream formal errors, which are 10-30 times smaller than the differences between two
  reasonable models.
- a TCA whose spread over neighbouring degrees is >> its sigma is ``uncertain`` (issue 13): on
  the development days (1-10 April) every TCA more than 5 s from upstream's is; 11-15 April are
  the hold-out, checked only at the end and reported in docs/smooth.md.

Run ``python tests/pipeline/test_realdata_smooth.py`` to print the table of docs/smooth.md.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from realdata import DOPTRACK, requires

BAD_PASS = "202004011959"
#: 11-15 April are the project's hold-out: the smoother was developed on 1-10 April only.
HOLDOUT_FIRST_DAY = 11

pytestmark = requires(DOPTRACK / "data")


def smooth_all() -> pd.DataFrame:
    """One row per DopTrack pass: our fit, TCA and fca against the YAML's."""
    from trackproc.io.tabular import read_raw
    from trackproc.pipeline.ingest import ingest
    from trackproc.pipeline.smooth import smooth

    rows = []
    for path in sorted((DOPTRACK / "data").glob("*.csv")):
        table = ingest([read_raw(str(path))]).table
        result = smooth(table)
        assert len(result.fits) == 1, path
        rec = result.summary["fits"][0]
        up = table.meta["doptrack"][str(path)]
        row = {"pass": path.stem.rsplit("_", 1)[-1], "max_elev_deg": (up.get("prediction") or {}).get("max_elevation"),
               "n": rec["n_samples"], "rejected": rec["n_rejected"], "degree": rec.get("degree"),
               "rms_hz": rec.get("rms"), "status": rec["status"], "warnings": ",".join(rec["warnings"]),
               "largest_gap_s": rec.get("largest_gap_s"), "tca_error_s": up["tca_error_s"],
               "fca_error_hz": up["fca_error_hz"], "rho": rec["rho"], "n_eff": rec["n_eff"],
               "holdout": int(path.stem.rsplit("_", 1)[-1][6:8]) >= HOLDOUT_FIRST_DAY}
        tca = rec.get("tca") or {}
        row["tca_status"] = tca.get("status")
        if tca.get("status") in ("ok", "uncertain"):
            dt = (pd.Timestamp(tca["time_utc"]) - pd.Timestamp(up["tca"])).total_seconds()
            df = rec["fca_hz"] - up["fca_hz"]
            row.update({"dt_s": dt, "sigma_s": tca["sigma_s"], "spread_s": tca["degree_spread_s"],
                        "uncertainty_s": tca["uncertainty_s"],
                        "dfca_hz": df, "fca_sigma_hz": rec["fca_sigma_hz"], "fca_spread_hz": rec["fca_degree_spread_hz"]})
        else:
            row["tca_note"] = tca.get("error")
        rows.append(row)
    frame = pd.DataFrame(rows)
    frame["dt_in_yaml_err"] = frame["dt_s"] / frame["tca_error_s"]
    frame["dfca_in_yaml_err"] = frame["dfca_hz"] / frame["fca_error_hz"]
    frame["dt_in_sigma"] = frame["dt_s"] / frame["sigma_s"]
    frame["dt_in_total"] = frame["dt_s"] / np.hypot(frame["sigma_s"], frame["spread_s"].fillna(0.0))
    frame["dt_in_uncertainty"] = frame["dt_s"] / frame["uncertainty_s"]
    frame["dfca_in_sigma"] = frame["dfca_hz"] / frame["fca_sigma_hz"]
    frame["dfca_in_total"] = frame["dfca_hz"] / np.hypot(frame["fca_sigma_hz"], frame["fca_spread_hz"].fillna(0.0))
    return frame


@pytest.fixture(scope="module")
def results() -> pd.DataFrame:
    return smooth_all()


def test_all_44_passes_fitted_to_the_quantisation_level(results):
    assert len(results) == 44
    assert (results["status"] != "failed").all()
    # 2 Hz quantisation alone gives 0.58 Hz; the receiver adds about 1.5 Hz of jitter
    assert results["rms_hz"].between(0.58, 3.0).all(), results[["pass", "rms_hz"]]
    assert (results["rejected"] <= 0.05 * results["n"]).all()


def test_the_bad_pass_202004011959_is_reported_as_such(results):
    bad = results.set_index("pass").loc[BAD_PASS]
    assert bad["status"] == "suspect"
    assert set(bad["warnings"].split(",")) == {"tca_not_observed", "largest_gap"}
    assert "401.5 s data gap" in bad["tca_note"]
    assert math.isnan(bad["dt_s"])                        # no TCA claimed
    # the only pass where one gap covers most of the pass
    assert results.loc[results["warnings"].str.contains("largest_gap"), "pass"].tolist() == [BAD_PASS]


def test_tca_and_fca_against_the_doptrack_yaml(results):
    observed = results.dropna(subset=["dt_s"])          # TCA status ok or uncertain
    assert len(observed) >= 30
    # closest approach not observed: inside a gap > 30 s or within 30 s of an end of the data
    assert set(results.loc[results["dt_s"].isna(), "warnings"].str.split(",").sum()) >= {"tca_not_observed"}
    assert observed["dt_s"].abs().median() < 1.0
    assert observed["dfca_hz"].abs().median() < 20.0
    # the YAML's formal errors are far below the model-to-model differences ...
    assert observed["dt_in_yaml_err"].abs().median() > 5
    # ... while our sigma combined with the degree spread is of their size
    assert observed["dt_in_total"].abs().median() < 3
    assert observed["dfca_in_total"].abs().median() < 3
    # on high passes (max elevation >= 40 deg) the S-curve is steep and both models agree to 2.5 s
    high = observed[observed["max_elev_deg"] >= 40]
    assert len(high) >= 8 and (high["dt_s"].abs() < 2.5).all() and high["dt_s"].abs().median() < 0.5


def test_tca_status_uncertain_where_the_degree_spread_says_so(results):
    """Issue 13 item 4: a TCA whose degree spread is >> its sigma is ``uncertain``, not ``ok``.
    On the development days (1-10 April) every TCA more than 5 s from upstream's (the low passes
    202004032256, 202004042249) is uncertain, and the TCAs called ok are closer to upstream's than
    the uncertain ones, on both sets. The hold-out days (11-15 April) are reported in
    docs/smooth.md: one low pass there (202004151226, 10 deg, 13 s) is called ok with a spread of
    2.6 sigma: the degree spread is an indicator, not a guarantee."""
    observed = results.dropna(subset=["dt_s"])
    dev = observed[~observed["holdout"]]
    assert len(dev) >= 15
    far = dev[dev["dt_s"].abs() > 5.0]
    assert len(far) >= 1 and (far["tca_status"] == "uncertain").all(), far[["pass", "dt_s", "tca_status"]]
    for part in (dev, observed[observed["holdout"]]):
        ok, unsure = part[part["tca_status"] == "ok"], part[part["tca_status"] == "uncertain"]
        assert len(ok) >= 5 and len(unsure) >= 2
        assert ok["dt_s"].abs().median() < unsure["dt_s"].abs().median()
    # the uncertainty reported with an uncertain TCA covers its difference from upstream
    unsure = observed[observed["tca_status"] == "uncertain"]
    assert (unsure["dt_in_uncertainty"].abs() < 4).all(), unsure[["pass", "dt_s", "uncertainty_s"]]


def markdown(frame: pd.DataFrame) -> str:
    """The comparison table of docs/smooth.md."""
    frame = frame.copy()
    frame["dt_ok_in_uncertainty"] = frame["dt_in_uncertainty"].where(frame["tca_status"] == "ok")
    observed = frame.dropna(subset=["dt_s"])

    def stat(col, scale=1.0, fmt="{:.2f}"):
        values = observed[col].dropna().abs() * scale
        worst = observed.loc[values.idxmax(), "pass"]
        return fmt.format(values.median()), f"{fmt.format(values.max())} ({worst})"

    lines = ["| quantity | median abs | worst abs (pass) |", "|---|---|---|"]
    for label, col, fmt in [
        ("TCA difference, s", "dt_s", "{:.3f}"),
        ("TCA difference / YAML tca_error", "dt_in_yaml_err", "{:.1f}"),
        ("TCA difference / our sigma_s", "dt_in_sigma", "{:.1f}"),
        ("TCA difference / our sigma_s (+) degree spread", "dt_in_total", "{:.1f}"),
        ("TCA difference / uncertainty_s, TCA status ok", "dt_ok_in_uncertainty", "{:.1f}"),
        ("fca difference, Hz", "dfca_hz", "{:.2f}"),
        ("fca difference / YAML fca_error", "dfca_in_yaml_err", "{:.1f}"),
        ("fca difference / our fca_sigma_hz", "dfca_in_sigma", "{:.1f}"),
        ("fca difference / our sigma (+) degree spread", "dfca_in_total", "{:.1f}"),
    ]:
        med, worst = stat(col, fmt=fmt)
        lines.append(f"| {label} | {med} | {worst} |")
    lines.append("")
    lines.append("| pass | max elev deg | n | rejected | degree | rho | n_eff | RMS Hz | status | dt s | sigma s | spread s "
                 "| YAML tca_error s | dfca Hz | fca sigma Hz | YAML fca_error Hz |")
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for _, r in frame.iterrows():
        if math.isnan(r["dt_s"]):
            cells = ["—"] * 3 + [f"{r['tca_error_s']:.3f}", "—", "—", f"{r['fca_error_hz']:.2f}"]
            status = f"{r['status']} ({r['warnings']})"
        else:
            cells = [f"{r['dt_s']:+.3f}", f"{r['sigma_s']:.3f}", f"{r['spread_s']:.3f}", f"{r['tca_error_s']:.3f}",
                     f"{r['dfca_hz']:+.2f}", f"{r['fca_sigma_hz']:.2f}", f"{r['fca_error_hz']:.2f}"]
            status = r["status"] + (f" ({r['warnings']})" if r["warnings"] else "")
        lines.append(f"| {r['pass']}{' (hold-out)' if r['holdout'] else ''} | {r['max_elev_deg']} | {r['n']} | "
                     f"{r['rejected']} | {r['degree']} | {r['rho']:.2f} | {r['n_eff']:.0f} | "
                     f"{r['rms_hz']:.2f} | {status} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":   # pragma: no cover - regenerates the docs table
    print(markdown(smooth_all()))
