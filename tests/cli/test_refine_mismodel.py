"""``refine`` on passes whose errors its models do not know (issue 13, "fix the class"): the rule is
*cover or say so* — every component of the state at the solution epoch within 4 sigma of the truth,
or a verdict other than ``ok`` for a related reason, or a refusal whose kept covariance covers, or
exit 1 (no convergence).

The truth is known: the seed 004 Table 1 orbit (tests/report/test_refine.py) over a station placed
so that it is the traverse point of a pass, seen at S-band (2.2 GHz, 0.1 Hz noise, 55 deg) and at VHF
like DopTrack (145.9 MHz, 1.5 Hz noise, 0.3 Hz/s drift; 55 deg and a low 16 deg pass), the stale
state of Table 1 with its covariance (10 km, 5 m/s: it covers the stale error) and without (the
default a-priori, which the stale state contradicts: chi2 125 over 6). The mis-modellings: an
oscillator excursion (a 20 Hz thermal step, a 5 Hz sine), a slant-factor ionosphere, a second signal
on 10 % of the samples, a gap, half a pass, 60 s of a pass, a carrier 3 kHz off, a two-way pass
labelled one-way. The table of docs/refine.md ("Mis-modelled passes") is
``python benchmarks/refine_mismodel.py``.

Independent references: the truth of the simulation; the chi-square law of the a-priori innovation
(Monte Carlo of a linear Gaussian problem); and, for a time-tag offset, the closed form of the orbit
the pass cannot tell from the truth (the truth shifted in time and turned with the Earth), whose
derivative is the direction of the ``--time-tag-sigma`` consider term.
"""

from __future__ import annotations

import json
import math
from functools import lru_cache

import numpy as np
import pytest
from scipy import stats

from trackproc.io.passfile import PassTable, write_pass_table
from trackproc.io.statefile import State
from trackproc.methods import quality as qm
from trackproc.pipeline.refine import RefineOptions, refine, traverse_station
from trackproc.pipeline.simulate import SimulateOptions, simulate

from refine_outcomes import refine_outcome
from test_refine import EOP, EPOCH, STALE, STALE_RV, TRUTH, truth_at

STALE_NO_COV = State.from_vectors(EPOCH, STALE_RV[:3], STALE_RV[3:])
STALES = {"cov": STALE, "nocov": STALE_NO_COV}
#: the passes: station cross-track distance (m), carrier (Hz), noise (Hz), offset (Hz), drift (Hz/s)
GEOMETRIES = {"S55": (500e3, 2.2e9, 0.1, 150.0, 0.0), "V55": (500e3, 145.9e6, 1.5, 150.0, 0.3),
              "V16": (1800e3, 145.9e6, 1.5, 150.0, 0.3)}
#: the Earth's rotation rate (rad/s; IERS)
OMEGA_EARTH = 7.292115e-5


@lru_cache(maxsize=None)
def _simulated(geometry: str, seed: int, mode: str = "one-way"):
    cross, carrier, sigma, offset, drift = GEOMETRIES[geometry]
    station, _ = traverse_station(TRUTH, cross_track_m=cross, eop=EOP)
    one_way = mode == "one-way"
    sim = simulate(TRUTH, {station.name: station},
                   SimulateOptions(duration_s=1800, step_s=1.0, start=np.datetime64("2026-03-20T09:15:00"),
                                   carrier_hz=carrier, seed=seed, kinds=("doppler",), mode=mode,
                                   sigma_doppler_hz=sigma, freq_offset_hz=offset if one_way else 0.0,
                                   freq_drift_hz_s=drift if one_way else 0.0), EOP)
    return station, sim


def mismodelled(geometry: str, scenario: str, seed: int = 1) -> tuple:
    """The pass of ``geometry`` with the error ``scenario``: ``(PassTable, stations or None)``."""
    station, sim = _simulated(geometry, seed, "two-way" if scenario == "twoway_as_oneway" else "one-way")
    frame = sim.frame.copy()
    meta = json.loads(json.dumps(sim.meta))
    t = (frame["time"].dt.tz_localize(None) - np.datetime64("2026-03-20T09:30:00")).dt.total_seconds().to_numpy()
    v = frame["value"].to_numpy().copy()
    rng = np.random.default_rng(1000 + seed)
    mid = 0.5 * (t.min() + t.max())
    keep = np.ones(t.size, bool)
    stations = None
    if scenario.startswith("timetag"):                    # every sample's time tag late by dt
        frame["time"] = frame["time"] + np.timedelta64(int(float(scenario[7:]) * 1e9), "ns")
    elif scenario.startswith("station_"):                 # the station's coordinates off
        north, east, up = {"station_n1k": (1e3, 0, 0), "station_e1k": (0, 1e3, 0), "station_u100": (0, 0, 100.0),
                           "station_n200": (200.0, 0, 0)}[scenario]
        lat = station.lat_deg + math.degrees(north / 6371e3)
        lon = station.lon_deg + math.degrees(east / (6371e3 * math.cos(math.radians(station.lat_deg))))
        stations = {station.name: type(station)(station.name, lat, lon, station.height_m + up)}
    elif scenario == "carrier+3k":
        meta["carrier_hz"] = meta["carrier_hz"] + 3e3
    elif scenario == "twoway_as_oneway":
        meta["doppler_mode"] = "one-way"
    elif scenario == "thermal20":                         # a 20 Hz step, 60 s time constant, mid-pass
        v += np.where(t > mid, 20.0 * (1.0 - np.exp(-(t - mid) / 60.0)), 0.0)
    elif scenario == "sine5":                             # 5 Hz, 200 s period
        v += 5.0 * np.sin(2.0 * np.pi * t / 200.0 + rng.uniform(0.0, 2.0 * np.pi))
    elif scenario == "gap90":
        keep = np.abs(t - mid) > 45.0
    elif scenario == "first_half":                        # closest approach (t = 0) not observed
        keep = t < -5.0
    elif scenario == "pass60":
        keep = np.abs(t) <= 30.0
    elif scenario == "tone10pct":                         # a second signal 300 Hz away on 10 % of the samples
        hit = rng.random(v.size) < 0.1
        v[hit] += 300.0
    elif scenario == "bursts":                            # three bursts of 10 outliers
        scale = 30.0 * GEOMETRIES[geometry][2] if GEOMETRIES[geometry][2] < 1.0 else 30.0
        for _ in range(3):
            i = int(rng.integers(0, v.size - 10))
            v[i:i + 10] += rng.normal(0.0, scale, 10)
    elif scenario == "iono":                              # 3 Hz x the slant factor 1/sin(el + 10 deg)
        times = np.asarray(sim.grid["times"]).astype("datetime64[ns]")
        el = np.asarray(sim.grid["elevation_rad"]).reshape(times.size, -1)[:, 0]
        idx = np.searchsorted(times, frame["time"].dt.tz_localize(None).to_numpy().astype("datetime64[ns]"))
        v += 3.0 / np.sin(el[idx] + math.radians(10.0))
    elif scenario != "clean":
        raise ValueError(scenario)
    frame["value"] = v
    return PassTable(frame[keep].reset_index(drop=True), meta), stations


def outcome(geometry: str, scenario: str, stale: str, seed: int = 1) -> dict:
    """Refine the mis-modelled pass: the largest |error|/sigma over x..vz at the solution epoch, the
    verdict, the reasons that are not ``ok``, refused or not, or ``failed`` (exit 1)."""
    table, stations = mismodelled(geometry, scenario, seed)
    out = refine_outcome(table, STALES[stale], stations, RefineOptions(), EOP, truth_at)
    if "result" in out:
        out.update(reasons=[c for c, r in out["reasons"].items() if r["severity"] != "ok"],
                   refused=out["result"].state.diagnostics["refused"] is not None)
    return out


def covers_or_says_so(out: dict) -> bool:
    """The rule: covered within 4 sigma, or exit 1, or a verdict that is not ``ok`` for a reason
    other than the pass's low elevation alone (``low_pass`` is said of every low pass)."""
    if "failed" in out or out["max_z"] < 4.0:
        return True
    return out["verdict"] != "ok" and bool(set(out["reasons"]) - {"low_pass"})


# ----------------------------------------------------------------------------- the statistic

def test_prior_innovation_is_chi2_and_keeps_its_power_on_a_weak_pass():
    """Linear Gaussian problem like one weak pass: in the a-priori's whitened coordinates the data's
    information is 100, 30 and 0.5 along three directions and (almost) nothing along three (the
    rotation the pass cannot see), with two nuisance columns (offset, drift). The innovation of the
    a-priori is chi2 with the 3 directions it uses (Monte Carlo mean, 99.9 % false-alarm rate,
    Kolmogorov-Smirnov); with the stale state 8 a-priori sigmas off along the faint direction it fires
    on most draws, while the a-priori's share of chi2 against chi2(6) (the test before) almost never
    does: the data move the state only a third of the way there (0.5/(1 + 0.5))."""
    rng = np.random.default_rng(11)
    m, n = 120, 6
    lam = np.array([100.0, 30.0, 0.5, 1e-4, 1e-6, 0.0])
    q, _ = np.linalg.qr(rng.normal(size=(m, n + 2)))
    low = np.diag([1.0, 2.0, 1.5, 0.5, 1.0, 3.0])                  # P = L Lᵀ
    p = low @ low.T
    a_full = np.hstack([q[:, :n] * np.sqrt(lam) @ np.linalg.inv(low), q[:, n:] * 10.0])
    info = a_full.T @ a_full
    info[:n, :n] += np.linalg.inv(p)
    cov = np.linalg.inv(info)

    def draw(x_true):
        y = a_full @ np.r_[x_true, rng.normal(0.0, 10.0, 2)] + rng.normal(size=m)
        delta = (cov @ (a_full.T @ y))[:n]                          # the a-priori centre is 0
        return qm.prior_innovation_chi2(delta, p, cov[:n, :n]), float(delta @ np.linalg.solve(p, delta))

    null = [draw(low @ rng.normal(size=n)) for _ in range(3000)]
    t = np.array([s[0][0] for s in null])
    assert all(s[0][1] == 3 for s in null)
    assert abs(t.mean() / 3.0 - 1.0) < 0.05, t.mean()
    assert np.sum(t > qm.chi2_limit(3)) <= stats.binom.ppf(0.9999, t.size, 1e-3)
    assert stats.kstest(t, "chi2", args=(3,)).pvalue > 1e-3
    faint = [draw(low @ np.r_[rng.normal(size=2), 8.0, rng.normal(size=3)]) for _ in range(300)]
    new = np.mean([s[0][0] > qm.chi2_limit(3) for s in faint])
    old = np.mean([s[1] > qm.chi2_limit(6) for s in faint])
    print(f"stale 8 sigma off along the faint direction: innovation fires {new:.2f}, share vs chi2(6) {old:.2f}")
    assert new > 0.6 and old < 0.1


# ----------------------------------------------------------------------------- the scenario table

#: the scenarios of the fast tier (seed 1): cases that were ``ok`` at 6-9 sigma before the
#: innovation test and the stated-covariance rule, and one of each kind of error
FAST = [("V55", "first_half", "nocov"), ("V55", "sine5", "nocov"), ("V16", "clean", "nocov"),
        ("V55", "iono", "cov"), ("S55", "iono", "cov"), ("S55", "thermal20", "cov"), ("S55", "tone10pct", "nocov"),
        ("V55", "twoway_as_oneway", "cov"), ("S55", "clean", "nocov")]
#: more of the table (slow tier): the other scenarios one can detect, both a-priori, both passes
SLOW = [(g, s, a) for g in ("S55", "V55", "V16")
        for s in ("clean", "carrier+3k", "thermal20", "sine5", "gap90", "first_half", "tone10pct", "bursts",
                  "station_n200", "station_u100")
        for a in ("cov", "nocov") if (g, s, a) not in FAST
        # the stale state contradicts the default a-priori where these passes cannot look (docs/refine.md,
        # "Mis-modelled passes": undetectable by the pass); a 60 s pass sees nothing of it either
        and not (a == "nocov" and (g == "V16" or (g, s) == ("V55", "thermal20")))]


@pytest.mark.parametrize("geometry,scenario,stale", FAST)
def test_mismodelled_pass_is_covered_or_said(geometry, scenario, stale):
    out = outcome(geometry, scenario, stale)
    assert covers_or_says_so(out), {k: v for k, v in out.items() if k != "result"}
    if out.get("refused"):
        assert out["max_z"] < 4.0                           # the kept covariance covers the stale state


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3])
def test_mismodelled_table_is_covered_or_said(seed):
    """The rest of the table on two more noise draws: every row covers or says so."""
    bad = {}
    for case in SLOW:
        out = outcome(*case, seed=seed)
        if not covers_or_says_so(out):
            bad[case] = {k: v for k, v in out.items() if k != "result"}
    assert not bad, bad


# ----------------------------------------------------------------------------- undetectable in principle

@pytest.mark.parametrize("dt", [0.5, 2.0])
def test_time_tag_offset_is_the_truth_shifted_and_turned_with_the_earth(dt):
    """Time tags late by ``dt``: the samples are those of the truth shifted by ``-dt`` in time and
    turned by ``omega dt`` about the Earth's axis (the station is where it is ``dt`` later; J2 is
    axisymmetric): an orbit as good as the truth for every sample, which no residual test can tell
    from it. refine finds that orbit (within 0.5 sigma) and says ``ok``: the error, ~7.4 km/s x
    ``dt`` along-track (37 sigma at 2 s on the S-band pass), is documented, not detected."""
    out = outcome("S55", f"timetag{dt}", "cov")
    res = out["result"]
    epoch = np.datetime64(res.state.epoch, "ns")
    shifted = truth_at(epoch - np.timedelta64(int(dt * 1e9), "ns"))
    c, s = math.cos(OMEGA_EARTH * dt), math.sin(OMEGA_EARTH * dt)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    equivalent = np.r_[turn @ shifted[:3], turn @ shifted[3:]]
    z_equivalent = (res.state.values[:6] - equivalent) / res.state.sigma[:6]
    assert np.all(np.abs(z_equivalent) < 0.5), z_equivalent
    assert out["verdict"] == "ok" and out["max_z"] > 4.0 * dt


def test_time_tag_direction_is_the_derivative_of_the_equivalent_orbit():
    """:func:`time_tag_direction` (the force model's acceleration, the Earth's spin) against the
    central difference of the equivalent orbit of the test above built from the simulator's
    reference propagation (DOP853), at the Table 1 traverse point: to 1e-3 of its size."""
    from trackproc.pipeline.refine import prepare
    from trackproc.pipeline.refine.traverse import time_tag_direction

    table, _ = mismodelled("S55", "clean")
    ref = prepare(table, STALE, None, RefineOptions(), EOP)
    epoch = np.datetime64(ref.problem.epoch, "ns")
    x = truth_at(epoch)

    def equivalent(dt):
        shifted = truth_at(epoch - np.timedelta64(int(round(dt * 1e9)), "ns"))
        c, s = math.cos(OMEGA_EARTH * dt), math.sin(OMEGA_EARTH * dt)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return np.r_[turn @ shifted[:3], turn @ shifted[3:]]

    numeric = (equivalent(0.01) - equivalent(-0.01)) / 0.02
    g = time_tag_direction(ref, x)
    assert np.linalg.norm(g[:3] - numeric[:3]) < 1e-3 * np.linalg.norm(numeric[:3])
    assert np.linalg.norm(g[3:] - numeric[3:]) < 1e-3 * np.linalg.norm(numeric[3:])


@pytest.mark.parametrize("geometry,stale,dt", [("S55", "cov", 2.0), ("V55", "nocov", 2.0)])
def test_a_stated_time_tag_uncertainty_covers_the_offset(geometry, stale, dt):
    """``time_tag_sigma_s`` (``--time-tag-sigma``) adds the offset's effect to the covariance as a
    consider parameter: time tags 2 s late, stated 2 s: 37 and 13 sigma before, within 2 now."""
    table, stations = mismodelled(geometry, f"timetag{dt}")
    res = refine(table, STALES[stale], stations, RefineOptions(time_tag_sigma_s=dt), EOP)
    z = (res.state.values[:6] - truth_at(res.state.epoch)) / res.state.sigma[:6]
    assert np.all(np.abs(z) < 2.0), z
    consider = res.state.diagnostics["time_tag_consider"]        # absent without --time-tag-sigma
    assert consider["sigma_s"] == dt and 0.8 * 7.4e3 * dt < consider["position_sigma_m"] < 1.2 * 7.4e3 * dt


def test_cli_says_so_for_a_stated_covariance_the_pass_contradicts(run_cli, tmp_path):
    """The VHF pass with a slant-factor ionosphere (3 Hz / sin(el + 10 deg)): the orbit absorbs it
    (white residuals) and contradicts the stale file's covariance, a stated a-priori: refine declines
    the pass, keeps the stale state with its covariance and says ``suspect`` (``declined``):
    ``--strict`` exits 1, the file written all the same."""
    table, _ = mismodelled("V55", "iono")
    write_pass_table(table, str(tmp_path / "pass.parquet"))
    (tmp_path / "stale.json").write_text(json.dumps({
        "epoch": EPOCH, "frame": "GCRF", "position_m": STALE_RV[:3].tolist(), "velocity_m_s": STALE_RV[3:].tolist(),
        "covariance": np.diag([1e8, 1e8, 1e8, 25.0, 25.0, 25.0]).tolist()}))
    out = tmp_path / "refined.json"
    r = run_cli(["refine", str(tmp_path / "pass.parquet"), "--initial", str(tmp_path / "stale.json"), "--dut1", "0",
                 "-o", str(out), "--strict"])
    doc = json.loads(out.read_text())
    reasons = {x["code"]: x for x in doc["quality"]["reasons"]}
    assert r.exit_code == 1 and doc["quality"]["verdict"] == "suspect", r.stderr
    assert reasons["declined"]["severity"] == "suspect"
    assert "stated a-priori" in reasons["declined"]["message"] and "likely culprit" in reasons["declined"]["message"]
    assert doc["diagnostics"]["decision"]["action"] == "declined"
    np.testing.assert_allclose(doc["at_stale_epoch"]["position_m"], STALE_RV[:3], rtol=0, atol=1e-3)
    assert "Traceback" not in r.stderr
