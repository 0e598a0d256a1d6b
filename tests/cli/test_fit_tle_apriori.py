"""``fit-tle``'s a-priori conflict check (reason ``apriori_conflict``) under the fit's own error
model (issue 18, docs/fit-tle.md "Refusal"): the score test of the initial TLE's a-priori with
SGP4's per-pass theory error (:func:`trackproc.methods.tle_theory_error.apriori_conflict_chi2`), against
independent references:

* a simulated ISS Doppler pass (``trackproc simulate`` from the TLE) whose time tags are shifted by
  0.5 s (3.8 km along-track: ~6 of the TLE a-priori's sigmas there, 0.4 of the theory error's) is
  not rejected: verdict ``suspect`` (refused: one pass), exit 0, the same in the JSON summary
  and on the stderr's last line (the check before, on the least-squares solution, rejected it);
* the same pass fitted from a TLE moved 1 degree along-track (117 km, ~13 sigmas of the theory
  error): ``rejected`` (a-priori conflict), exit 1, the TLE written;
* DopTrack 202004011959 (the README's bad pass: its closest approach in a 400 s gap, 100 s off
  in time), a development day: ``rejected`` (a-priori conflict), exit 1.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tle_reference import ISS
from trackproc.io.tle import MeanElements, format_tle, parse_tle, satrec, tle_epoch
from trackproc.methods import tle_fit as tf


def _one_pass(run_cli, tmp_path, shift_s: float = 0.0):
    """One ISS pass at ZHY (2019-12-10 12:39-12:45 UTC, 0.83 days after the TLE's epoch), 2 s
    Doppler samples at 145.8 MHz with 1 Hz noise, simulated by ``trackproc simulate`` from the
    TLE; the time tags then shifted by ``shift_s`` (the satellite seen ``shift_s`` late)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    (tmp_path / "iss.tle").write_text(ISS)
    (tmp_path / "st.csv").write_text("station,lat_deg,lon_deg,height_m\nZHY,50.25,28.66,230\n")
    out = tmp_path / "pass.parquet"
    res = run_cli(["simulate", "--tle", tmp_path / "iss.tle", "--stations", tmp_path / "st.csv",
                   "--start", "2019-12-10T12:35:00Z", "--duration", "900", "--step", "2", "--kinds", "doppler",
                   "--carrier-hz", "145.8e6", "--sigma-doppler-hz", "1.0", "--seed", "11", "--dut1", "0", "-o", out])
    assert res.exit_code == 0, res.stderr
    if shift_s:
        table = pq.read_table(out)
        k = table.schema.get_field_index("time")
        shifted = pa.compute.add(table.column(k), pa.scalar(np.timedelta64(int(round(shift_s * 1e9)), "ns"),
                                                           pa.duration("ns")))
        table = table.set_column(k, table.schema.field(k), shifted.cast(table.schema.field(k).type))
        pq.write_table(table, out)
    return out


def _fit(run_cli, tmp_path, pass_file, initial, *extra):
    res = run_cli(["fit-tle", pass_file, "--initial", initial, "--dut1", "0", "-o", tmp_path / "out.tle",
                   "--summary", tmp_path / "fit.json", *extra])
    doc = json.loads((tmp_path / "fit.json").read_text())
    reasons = {r["code"]: r for r in doc["quality"]["reasons"]}
    return res, doc, reasons


def test_a_time_tag_shift_within_the_theory_error_is_not_a_conflict(run_cli, tmp_path):
    pass_file = _one_pass(run_cli, tmp_path, shift_s=0.5)
    res, doc, reasons = _fit(run_cli, tmp_path, pass_file, tmp_path / "iss.tle")
    print("a-priori:", doc["apriori"], [(r["code"], r["severity"]) for r in doc["quality"]["reasons"]])
    # the time shift is there, and large against the TLE's own along-track sigma
    shift = doc["groups"][0]["time_shift_initial_s"]
    assert shift == pytest.approx(0.5, abs=0.1), shift
    assert reasons["timing"]["value"] > 3 * reasons["timing"]["limit"]
    # consistent with the theory error: no conflict; one pass: refused, suspect, exit 0
    assert reasons["apriori_conflict"]["severity"] == "ok", reasons["apriori_conflict"]
    assert doc["apriori"]["chi2"] == reasons["apriori_conflict"]["value"] <= reasons["apriori_conflict"]["limit"]
    assert doc["apriori"]["least_squares_share"] > reasons["apriori_conflict"]["limit"]   # what rejected it before
    assert doc["quality"]["verdict"] == "suspect" and doc["refused"]["code"] == "single_pass"
    assert res.exit_code == 0, res.stderr
    assert res.stderr.strip().splitlines()[-1].strip() == "quality: suspect (refused)", res.stderr
    assert parse_tle((tmp_path / "out.tle").read_text()).line2 == parse_tle(ISS).line2     # the initial TLE
    # --json: the same verdict on stderr; --strict: exit 1 for the suspect
    res = run_cli(["fit-tle", pass_file, "--initial", tmp_path / "iss.tle", "--dut1", "0", "-o", tmp_path / "j.tle",
                   "--json"])
    assert res.exit_code == 0 and json.loads(res.stderr)["quality"]["verdict"] == "suspect", res.stderr
    res = run_cli(["fit-tle", pass_file, "--initial", tmp_path / "iss.tle", "--dut1", "0", "-o", tmp_path / "s.tle",
                   "--strict"])
    assert res.exit_code == 1 and "suspect" in res.stderr.strip().splitlines()[-1], res.stderr


def test_a_gross_orbit_error_is_still_a_conflict(run_cli, tmp_path):
    pass_file = _one_pass(run_cli, tmp_path)
    truth = parse_tle(ISS)
    x = tf.elements_of(satrec(truth))
    c = tf.classical(x + np.r_[0, 0, 0, 0, 0, 1.0, 0])              # 1 degree along-track (117 km)
    moved = format_tle(MeanElements(tle_epoch(truth), c["inclination_deg"], c["raan_deg"], c["eccentricity"],
                                    c["arg_perigee_deg"], c["mean_anomaly_deg"], c["mean_motion_rev_day"],
                                    c["bstar"]), truth)
    (tmp_path / "moved.tle").write_text(moved.line1 + "\n" + moved.line2 + "\n")
    res, doc, reasons = _fit(run_cli, tmp_path, pass_file, tmp_path / "moved.tle")
    print("a-priori:", doc["apriori"], [(r["code"], r["severity"]) for r in doc["quality"]["reasons"]])
    assert reasons["apriori_conflict"]["severity"] == "rejected", reasons["apriori_conflict"]
    assert doc["quality"]["verdict"] == "rejected" and res.exit_code == 1, res.stderr
    assert "exit 1" in res.stderr.strip().splitlines()[-1] and "apriori_conflict" in res.stderr, res.stderr
    assert (tmp_path / "out.tle").exists()
    # and without the gross error, from the truth: no conflict
    _, doc, reasons = _fit(run_cli, tmp_path, pass_file, tmp_path / "iss.tle")
    assert reasons["apriori_conflict"]["severity"] == "ok", reasons["apriori_conflict"]


@pytest.mark.realdata
def test_doptrack_bad_pass_is_rejected_as_an_apriori_conflict(run_cli, tmp_path):
    from realdata import DOPTRACK

    raw = DOPTRACK / "data" / "Delfi-C3_32789_202004011959.csv"
    if not raw.exists():
        pytest.skip(f"real data not available: {raw}")
    pass_file = tmp_path / "p.parquet"
    assert run_cli(["ingest", raw, "-o", pass_file]).exit_code == 0
    res, doc, reasons = _fit(run_cli, tmp_path, pass_file, "metadata")
    print("a-priori:", doc["apriori"], [(r["code"], r["severity"]) for r in doc["quality"]["reasons"]])
    assert reasons["apriori_conflict"]["severity"] == "rejected", reasons["apriori_conflict"]
    assert doc["quality"]["verdict"] == "rejected" and res.exit_code == 1, res.stderr
    assert "exit 1" in res.stderr.strip().splitlines()[-1], res.stderr
