"""``refine`` and ``estimate`` from a TLE whose pass is late (docs/refine.md, "Timing"; pipeline/timing.py).

A station's time tags 1 s late move one pass's refined state 7.7 km along the ISS's track, with
a posterior sigma of tens of metres: a confident wrong answer. The along-track move is tested
against the TLE's accuracy (TLE differencing): beyond it the covariance takes the shift as a
possible time-tag error and the verdict is ``suspect`` (reason ``timing``). Reference: the
simulation's own truth (the TLE's SGP4 state at the start, propagated by the reference
integrator), per component in the refined covariance.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from test_refine_cli import ISS_TLE
from trackproc.io.statefile import read_state


@pytest.fixture(scope="module")
def iss_pass(tmp_path_factory):
    """An ISS pass simulated from its TLE over a station 400 km off its track (2 s Doppler samples,
    a -40 Hz transmitter offset), the truth at the start, and the same pass with its time tags 1 s late."""
    from trackproc.cli import app as cli_app
    from trackproc.dynamics import timescales as ts
    from trackproc.io.tle import parse_tle, tle_state
    from trackproc.pipeline.refine import traverse_station

    d = tmp_path_factory.mktemp("timing")
    (d / "iss.tle").write_text(ISS_TLE)
    station, _ = traverse_station(tle_state(parse_tle(ISS_TLE), at=np.datetime64("2019-12-09T17:00:00")),
                                  cross_track_m=400e3, eop=ts.EarthOrientation())
    (d / "st.csv").write_text(f"station,lat_deg,lon_deg,height_m\nISS,{station.lat_deg:.6f},{station.lon_deg:.6f},0\n")
    assert cli_app.main([str(a) for a in [
        "simulate", "--tle", d / "iss.tle", "--stations", d / "st.csv", "--start", "2019-12-09T16:52:00Z",
        "--duration", "960", "--step", "2", "--kinds", "doppler", "--seed", "3", "--freq-offset-hz", "-40",
        "--truth", d / "truth.json", "-q", "-o", d / "p.parquet"]]) == 0
    table = pd.read_parquet(d / "p.parquet")
    import pyarrow.parquet as pq

    meta = pq.read_schema(d / "p.parquet").metadata
    late = table.assign(time=table["time"] + pd.Timedelta(seconds=1.0))
    import pyarrow as pa

    pq.write_table(pa.Table.from_pandas(late, preserve_index=False).replace_schema_metadata(meta), d / "late.parquet")
    return d


def _z(out, truth_path):
    """Refined minus true state over the refined sigma, per component (truth propagated to the epoch)."""
    from trackproc.dynamics import propagator

    truth = read_state(str(truth_path))
    state = read_state(str(out))
    dt = float((state.epoch - truth.epoch) / np.timedelta64(1, "ns")) * 1e-9
    traj = propagator.propagate(truth.r_m, truth.v_m_s, truth.epoch, [dt], force="j2").raise_for_outcome()
    err = np.r_[state.r_m, state.v_m_s] - traj.state(dt)
    return err / np.asarray(json.loads(out.read_text())["sigma"][:6])


def _refine(run_cli, d, name, *extra):
    out = d / f"{name}.json"
    res = run_cli(["refine", d / f"{name}.parquet", "--initial", d / "iss.tle", "-q", "-o", out, *extra])
    return res, (json.loads(out.read_text()) if out.exists() else None)


def test_a_pass_on_time_keeps_its_covariance_and_says_timing_ok(run_cli, iss_pass):
    """On time, the pass agrees with the TLE's stated accuracy: not declined; the TLE is replaced
    only when the refined state predicts better (then the timing test says ok), else kept."""
    res, doc = _refine(run_cli, iss_pass, "p")
    assert res.exit_code == 0, res.stderr
    reasons = {r["code"]: r for r in doc["quality"]["reasons"]}
    assert doc["quality"]["verdict"] == "ok", reasons
    action = doc["diagnostics"]["decision"]["action"]
    assert action in ("replaced", "kept")
    if action == "replaced":
        assert reasons["timing"]["severity"] == "ok", reasons["timing"]
        timing = doc["diagnostics"]["tle_timing"]
        assert not timing["inflated"] and abs(timing["shift_s"]) < 0.05, timing
    z = _z(iss_pass / "p.json", iss_pass / "truth.json")
    assert np.all(np.abs(z) < 4.0), z


def test_a_late_pass_is_declined_and_the_tle_kept_covers_the_truth(run_cli, iss_pass):
    """Time tags 1 s late: the pass contradicts the TLE's stated accuracy (a 7 km along-track move
    against 208 m): declined, the TLE's state kept with its own covariance, suspect; the truth (the
    TLE's orbit) within 4 sigma of what is written. Before the rule, the timing test inflated a
    7.3 km move's covariance instead (pipeline/timing.py, still applied to states that replace a TLE)."""
    res, doc = _refine(run_cli, iss_pass, "late")
    assert res.exit_code == 0, res.stderr
    reasons = {r["code"]: r for r in doc["quality"]["reasons"]}
    assert doc["quality"]["verdict"] == "suspect" and reasons["declined"]["severity"] == "suspect", reasons
    assert doc["diagnostics"]["decision"]["action"] == "declined"
    seen = doc["diagnostics"]["refused"]["refused_correction_rtn"]["seen"]
    assert abs(seen["along_m"]) > 3000.0                # what the declined solution would have moved
    z = _z(iss_pass / "late.json", iss_pass / "truth.json")
    assert np.all(np.abs(z) < 4.0), z
    assert np.all(np.isfinite(doc["at_stale_epoch"]["sigma"]))
    # cron: --strict turns the suspect verdict into exit 1, the file still written
    res, doc = _refine(run_cli, iss_pass, "late", "--strict")
    assert res.exit_code == 1 and doc is not None


def test_a_stale_state_file_is_not_tested_for_timing(run_cli, iss_pass, tmp_path):
    """No accuracy is known for a state file without covariance: no ``timing`` reason."""
    from trackproc.io.tle import parse_tle, tle_state

    st = tle_state(parse_tle(ISS_TLE), at=np.datetime64("2019-12-09T16:59:00"))
    (tmp_path / "stale.json").write_text(json.dumps({
        "epoch": "2019-12-09T16:59:00Z", "frame": "GCRF", "position_m": st.r_m.tolist(),
        "velocity_m_s": st.v_m_s.tolist()}))
    res = run_cli(["refine", iss_pass / "late.parquet", "--initial", tmp_path / "stale.json", "-q", "-o",
                   tmp_path / "o.json"])
    assert res.exit_code == 0, res.stderr
    doc = json.loads((tmp_path / "o.json").read_text())
    assert "timing" not in {r["code"] for r in doc["quality"]["reasons"]}
    assert doc["diagnostics"]["tle_timing"] is None


def _estimate(run_cli, d, name, *extra):
    out = d / f"est_{name}.json"
    res = run_cli(["estimate", d / f"{name}.parquet", "--initial", d / "iss.tle", "-q", "-o", out, *extra])
    return res, out


def test_estimate_from_a_tle_on_a_late_pass_is_suspect_and_covers_the_error(run_cli, iss_pass):
    """The same late pass through ``estimate`` with its defaults (the TLE's stated a-priori, an
    offset and a drift for the one-way Doppler): one pass contradicts the TLE and cannot vouch for
    itself, so the TLE is declined (kept, suspect) and covers the truth; the pass on time is not
    declined (kept or replaced, ok) and covers the truth too."""
    res, out = _estimate(run_cli, iss_pass, "late")
    assert res.exit_code == 0, res.stderr
    doc = json.loads(out.read_text())
    reasons = {r["code"]: r for r in doc["quality"]["reasons"]}
    assert doc["quality"]["verdict"] == "suspect" and reasons["declined"]["severity"] == "suspect", reasons
    assert doc["diagnostics"]["decision"]["action"] == "declined"
    z = _z(out, iss_pass / "truth.json")
    assert np.all(np.abs(z) < 4.0), z
    res, out = _estimate(run_cli, iss_pass, "p")
    assert res.exit_code == 0, res.stderr
    doc = json.loads(out.read_text())
    assert doc["diagnostics"]["decision"]["action"] in ("kept", "replaced"), doc["diagnostics"]["decision"]
    assert doc["quality"]["verdict"] == "ok", doc["quality"]
    assert np.all(np.abs(_z(out, iss_pass / "truth.json")) < 4.0)


def test_refine_opm_carries_the_quality_verdict_and_the_covariance(run_cli, iss_pass, tmp_path):
    """``refine --opm``: the state written by -o as an OPM, its verdict as ``COMMENT QUALITY``."""
    from trackproc.io.opm import parse_opm

    out, opm = tmp_path / "late.json", tmp_path / "late.opm"
    res = run_cli(["refine", iss_pass / "late.parquet", "--initial", iss_pass / "iss.tle", "--opm", opm,
                   "--object-name", "ISS", "-q", "-o", out])
    assert res.exit_code == 0, res.stderr
    text = opm.read_text()
    assert "COMMENT QUALITY verdict=suspect reasons=declined" in text and "OBJECT_NAME = ISS" in text
    doc, back = json.loads(out.read_text()), parse_opm(text)
    assert np.allclose(back["covariance"], np.asarray(doc["covariance"])[:6, :6], rtol=1e-12)
