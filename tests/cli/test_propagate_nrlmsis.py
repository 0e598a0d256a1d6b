"""``trackproc propagate --force full --drag --atmosphere nrlmsis`` with the space-weather options
``--f107``/``--f107a``/``--ap`` (issue 17): the run ends (exit 0) with the same orbit as the Python API
given the same model, names NRLMSIS 2.1 and its indices in the metadata, and the indices move the
orbit; misuse and a missing pymsis are one-line usage errors (exit 2). The physics is checked in
tests/io/test_drag_nrlmsis.py."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from trackproc.dynamics.forces import ForceModel, Spacecraft
from trackproc.dynamics.propagator import propagate
from trackproc.dynamics.timescales import EarthOrientation
from trackproc.io.ephemeris import read_ephemeris
from trackproc.io.icgem import load_field
from trackproc.io.statefile import read_state

STATE = {"epoch": "2020-04-05T00:00:00Z", "frame": "GCRF", "position_m": [6778137.0, 0.0, 0.0],
         "velocity_m_s": [0.0, -948.4, 7609.4], "spacecraft": {"mass_kg": 2.2, "drag_area_m2": 0.01}}
RUN = ["--span", "1800", "--step", "600", "--force", "full", "--gravity", "4x4", "--third-body", "none",
       "--dut1", "0", "--drag", "--atmosphere", "nrlmsis"]


@pytest.fixture
def state_file(write):
    return write("sat.json", json.dumps(STATE))


def _xyz(path):
    return read_ephemeris(str(path)).frame[["x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy()


def test_nrlmsis_propagation_runs_and_equals_the_python_api(run_cli, state_file, tmp_path):
    pytest.importorskip("pymsis")
    out = tmp_path / "eph.csv"
    res = run_cli(["propagate", str(state_file), *RUN, "--f107", "70", "--f107a", "75", "--ap", "9",
                   "-o", str(out)])
    assert res.exit_code == 0, res.stderr
    meta = read_ephemeris(str(out)).meta
    assert meta["force_model"] == "full (EIGEN-6S 4x4, drag (nrlmsis), relativity)"
    assert meta["constants"]["drag"] == {"atmosphere": "nrlmsis", "model": "NRLMSIS 2.1 (pymsis)", "f107": 70.0,
                                         "f107a": 75.0, "ap": 9.0}
    eop = EarthOrientation.constant(0.0)
    fm = ForceModel(load_field(degree=4, date="2020-04-05T00:00:00"), third_bodies=(), drag=True, eop=eop,
                    spacecraft=Spacecraft(mass_kg=2.2, drag_area_m2=0.01), atmosphere="nrlmsis",
                    f107=70.0, f107a=75.0, ap=9.0)
    initial = read_state(str(state_file))
    t = np.array([0.0, 600.0, 1200.0, 1800.0])
    ref = propagate(initial.r_m, initial.v_m_s, initial.epoch, t, force=fm, eop=eop).state(t)
    got = _xyz(out)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)
    # the defaults (F10.7 = F10.7a = 150, Ap = 4): a denser atmosphere at 400 km, another orbit
    out2 = tmp_path / "eph2.csv"
    assert run_cli(["propagate", str(state_file), *RUN, "-o", str(out2)]).exit_code == 0
    assert read_ephemeris(str(out2)).meta["constants"]["drag"]["f107"] == 150.0
    assert 1e-3 < np.abs(_xyz(out2)[:, :3] - got[:, :3]).max() < 100.0


@pytest.mark.parametrize("args, words", [
    (["--atmosphere", "harris-priester", "--f107", "70"], "--f107: only with --drag --atmosphere nrlmsis"),
    (["--no-drag", "--atmosphere", "nrlmsis", "--ap", "4"], "--ap: only with --drag --atmosphere nrlmsis"),
    (["--atmosphere", "nrlmsis", "--f107a", "0"], "--f107a: expected a positive number, got 0.0"),
    (["--atmosphere", "nrlmsis", "--ap", "-1"], "--ap: expected a non-negative number, got -1.0"),
])
def test_space_weather_misuse_is_a_usage_error(run_cli, state_file, tmp_path, args, words):
    pytest.importorskip("pymsis")
    out = tmp_path / "eph.csv"
    res = run_cli(["propagate", str(state_file), "--span", "600", "--step", "600", "--force", "full", "--drag",
                   *args, "-o", str(out)])
    assert res.exit_code == 2 and words in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not out.exists()


def test_space_weather_with_another_force_is_a_usage_error(run_cli, state_file):
    res = run_cli(["propagate", str(state_file), "--span", "600", "--step", "600", "--force", "j2", "--f107", "70"])
    assert res.exit_code == 2 and "--f107: only with --force full" in res.stderr, res.stderr


def test_without_pymsis_nrlmsis_is_a_one_line_usage_error(run_cli, state_file, tmp_path, monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pymsis" else real(name, *a))
    out = tmp_path / "eph.csv"
    res = run_cli(["propagate", str(state_file), *RUN, "-o", str(out)])
    assert res.exit_code == 2, res.stderr
    assert res.stderr.strip() == ("trackproc: error: propagate: Invalid value for --atmosphere: nrlmsis needs the "
                                  "pymsis package (pip install pymsis); see 'trackproc propagate --help'")
    assert not out.exists()
