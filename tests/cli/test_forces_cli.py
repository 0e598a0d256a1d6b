"""``--force full`` at the command line (issue 17): the options defined once in
cli/force_options.py reach propagate, simulate and accuracy; full-only flags with another
force, a malformed spacecraft block, a bad field file are one-line usage errors (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from trackproc.dynamics.forces import ForceModel, Spacecraft
from trackproc.dynamics.propagator import propagate
from trackproc.io.ephemeris import read_ephemeris
from trackproc.io.icgem import load_field
from trackproc.io.statefile import read_state

V0 = [0.0, -927.7425636, 7555.8568340]
STATE = {"epoch": "2020-04-05T00:00:00Z", "frame": "GCRF", "position_m": [6878137.0, 0.0, 0.0], "velocity_m_s": V0,
         "spacecraft": {"mass_kg": 2.2, "srp_area_m2": 0.01, "drag_area_m2": 0.01, "cr": 1.3}}


@pytest.fixture
def state_file(write):
    return write("sat.json", json.dumps(STATE))


def test_propagate_full_matches_the_python_api_and_names_its_model(run_cli, state_file, tmp_path):
    out = tmp_path / "eph.csv"
    res = run_cli(["propagate", str(state_file), "--span", "1800", "--step", "600", "--force", "full",
                   "--gravity", "8x8", "--dut1", "0", "-o", str(out)])
    assert res.exit_code == 0, res.stderr
    eph = read_ephemeris(str(out))
    meta = eph.meta
    assert meta["force_model"] == "full (EIGEN-6S 8x8, sun+moon, srp, drag (harris-priester), relativity)"
    assert meta["constants"]["spacecraft"]["cr"] == 1.3 and meta["constants"]["gravity_field"]["degree"] == 8
    initial = read_state(str(state_file))
    from trackproc.dynamics.timescales import EarthOrientation

    eop = EarthOrientation.constant(0.0)
    fm = ForceModel(load_field(degree=8, date="2020-04-05T00:00:00"), srp=True, drag=True, eop=eop,
                    spacecraft=Spacecraft(2.2, 0.01, 1.3, 0.01))
    t = np.array([0.0, 600.0, 1200.0, 1800.0])
    ref = propagate(initial.r_m, initial.v_m_s, initial.epoch, t, force=fm, eop=eop).state(t)
    got = eph.frame[["x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)
    # --no-drag/--no-srp change the orbit (drag of a 2.2 kg cubesat at 500 km: metres in 30 min)
    out2 = tmp_path / "eph2.csv"
    assert run_cli(["propagate", str(state_file), "--span", "1800", "--step", "600", "--force", "full", "--gravity",
                    "8x8", "--no-drag", "--no-srp", "--dut1", "0", "-o", str(out2)]).exit_code == 0
    got2 = read_ephemeris(str(out2)).frame[["x_m", "y_m", "z_m"]].to_numpy()
    assert 1e-3 < np.abs(got2 - got[:, :3]).max() < 100.0


@pytest.mark.parametrize("args, words", [
    (["--force", "j2", "--gravity", "30"], "--gravity: only with --force full"),
    (["--force", "full", "--gravity", "abc"], "DEG or DEGxORD"),
    (["--force", "full", "--gravity", "10x20"], "order <= degree"),
    (["--force", "full", "--third-body", "sun,mars"], "sun, moon"),
    (["--force", "full", "--cd", "-1"], "from 0.5 to 5"),
    (["--force", "full", "--cr", "1e9", "--mass-kg", "1"], "from 0.5 to 3"),
    (["--force", "full", "--mass-kg", "1", "--srp-area-m2", "1000"], "area-to-mass"),
])
def test_bad_force_options_are_usage_errors(run_cli, state_file, tmp_path, args, words):
    res = run_cli(["propagate", str(state_file), "--span", "60", "--step", "60", "--dut1", "0", "-o",
                   str(tmp_path / "x.csv")] + args)
    assert res.exit_code == 2 and words in res.stderr and "Traceback" not in res.stderr


def test_drag_without_spacecraft_and_bad_spacecraft_block(run_cli, write, tmp_path):
    bare = write("bare.json", json.dumps({k: v for k, v in STATE.items() if k != "spacecraft"}))
    res = run_cli(["propagate", str(bare), "--span", "60", "--step", "60", "--force", "full", "--drag", "--dut1", "0",
                   "-o", str(tmp_path / "x.csv")])
    assert res.exit_code == 2 and "drag needs the spacecraft mass" in res.stderr
    bad = write("bad.json", json.dumps({**STATE, "spacecraft": {"mass_kg": "heavy"}}))
    res = run_cli(["propagate", str(bad), "--span", "60", "--step", "60", "--force", "full", "--dut1", "0",
                   "-o", str(tmp_path / "x.csv")])
    assert res.exit_code == 2 and "spacecraft.mass_kg" in res.stderr and "bad.json" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_bad_gravity_field_file_names_file_and_line(run_cli, state_file, write, tmp_path):
    gfc = write("f.gfc", "begin_of_head\nearth_gravity_constant 3.986e14\nradius 6378136.3\nmax_degree 2\n"
                         "end_of_head\ngfc 2 0 oops 0 0 0\n")
    res = run_cli(["propagate", str(state_file), "--span", "60", "--step", "60", "--force", "full", "--gravity", "2",
                   "--gravity-field", str(gfc), "--dut1", "0", "-o", str(tmp_path / "x.csv")])
    assert res.exit_code == 2 and "f.gfc, row 6" in res.stderr and "Traceback" not in res.stderr


def test_simulate_and_accuracy_take_full(run_cli, state_file, stations_csv, tmp_path):
    sim = tmp_path / "sim.csv"
    res = run_cli(["simulate", "--state", str(state_file), "--stations", str(stations_csv), "--duration", "7200",
                   "--step", "30", "--force", "full", "--gravity", "4", "--seed", "1", "--dut1", "0", "-o", str(sim)])
    assert res.exit_code == 0, res.stderr
    assert "full (EIGEN-6S 4x4" in sim.read_text()[:4000]
    stale = Path(__file__).resolve().parents[2] / "sample_data" / "stale.json"
    res = run_cli(["accuracy", str(stale), "--span", "600", "--step", "300", "--force", "full",
                   "--method", "monte-carlo", "-o", str(tmp_path / "a.csv")])
    assert res.exit_code == 2 and "--force full" in res.stderr


@pytest.mark.slow
def test_estimate_full_recovers_the_simulated_truth(run_cli, write, stations_csv, tmp_path):
    """Passes simulated with the full model (4x4 field, Sun, Moon), a perturbed initial state,
    estimate --force full with the same model: the truth within 4 sigma in every component."""
    truth = {k: v for k, v in STATE.items() if k != "spacecraft"}
    state = write("truth.json", json.dumps(truth))
    sim = tmp_path / "sim.parquet"
    args = ["--force", "full", "--gravity", "4", "--dut1", "0"]
    res = run_cli(["simulate", "--state", str(state), "--stations", str(stations_csv), "--duration", "21600",
                   "--step", "20", "--kinds", "range,range_rate", "--sigma-range-m", "2", "--sigma-range-rate-m-s",
                   "0.002", "--seed", "7", "-o", str(sim)] + args)
    assert res.exit_code == 0, res.stderr
    guess = dict(truth, position_m=[truth["position_m"][0] + 500.0, 300.0, -200.0],
                 velocity_m_s=[0.3, V0[1] - 0.2, V0[2] + 0.1])
    out = tmp_path / "fit.json"
    res = run_cli(["estimate", str(sim), "--initial", str(write("guess.json", json.dumps(guess))), "--stations",
                   str(stations_csv), "-o", str(out)] + args)
    assert res.exit_code == 0, res.stderr
    fit = json.loads(out.read_text())
    err = np.r_[np.subtract(fit["position_m"], truth["position_m"]), np.subtract(fit["velocity_m_s"], V0)]
    assert np.all(np.abs(err) < 4 * np.asarray(fit["sigma"][:6])), (err, fit["sigma"][:6])
    # ... and tight, not only covering: 6 h of samples determine the state better than one sample does,
    # position sigma below one range's noise (2 m), velocity sigma below one range-rate's (2 mm/s)
    assert np.all(np.asarray(fit["sigma"][:3]) < 2.0) and np.all(np.asarray(fit["sigma"][3:6]) < 0.002), fit["sigma"]
    assert fit["constants"]["gravity_field"]["degree"] == 4


def test_passes_and_compare_take_full(run_cli, tmp_path):
    """The force options reach passes and compare: a noiseless range pass simulated with the full
    model (8x8) 6 h after the state's epoch, at a pass ``passes --force full`` found, is matched
    by ``compare --force full`` with the same settings to well under a millimetre (measured 6e-7 m:
    the same dynamics, simulate's and compare's own measurement paths), while ``--force j2`` is
    off by the models' difference (measured 502 m RMS). The dynamics themselves are checked
    against Orekit in tests/io/test_forces_orekit.py."""
    sample = Path(__file__).resolve().parents[2] / "sample_data"
    cph = tmp_path / "cph.csv"
    cph.write_text("station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\n")
    schedule = tmp_path / "passes.json"
    res = run_cli(["passes", str(sample / "truth.json"), "--stations", str(cph), "--span", "1d", "--force", "full",
                   "--gravity", "8", "--min-elevation", "10", "--dut1", "0", "-o", str(schedule)])
    assert res.exit_code == 0, res.stderr
    doc = json.loads(schedule.read_text())
    rows = doc["passes"] if isinstance(doc, dict) else doc
    meta = doc.get("meta", doc) if isinstance(doc, dict) else {}
    assert "EIGEN-6S 8x8" in json.dumps(meta)
    later = [r for r in rows if r["aos_time"] >= "2026-03-20T15:30"]
    assert later, rows
    aos = later[0]["aos_time"][:19] + "Z"
    sim = tmp_path / "pass.parquet"
    res = run_cli(["simulate", "--state", str(sample / "truth.json"), "--stations", str(cph), "--start", aos,
                   "--duration", "300", "--step", "10", "--kinds", "range", "--sigma-range-m", "0", "--force", "full",
                   "--gravity", "8", "--dut1", "0", "-o", str(sim)])
    assert res.exit_code == 0, res.stderr
    rms = {}
    for force in ("full", "j2"):
        extra = ["--gravity", "8"] if force == "full" else []
        summary = tmp_path / f"{force}.json"
        res = run_cli(["compare", str(sim), str(sample / "truth.json"), "--remove", "none", "--force", force, *extra,
                       "--dut1", "0", "--summary", str(summary)])
        assert res.exit_code == 0, res.stderr
        (p,) = json.loads(summary.read_text())["passes"]
        rms[force] = p["rms"]
    assert rms["full"] < 1e-3 and rms["j2"] > 100.0, rms
