"""A station's time-tag offset as an estimable parameter (``estimate --station-time-bias``,
:class:`~trackproc.models.modifiers.StationTimeBias`): samples tagged ``τ`` late are the
measurement of the true time ``t - τ``, ``h_obs(t) = h(t - τ)``, ``∂h/∂τ = -ḣ(t - τ)``.

Independent references: the closed-form station on a sphere turning about GCRF z
(tests/pipeline/test_modifiers.py ``_meas``) for the moved reception times; the model evaluated
at the moved times without the bias for the value; a central difference of the whole model in
``τ`` for the partial, and for ranges the Doppler range-rate, which is ``dρ/dt_r`` in closed
form; and, end to end, the truth of a simulation whose one station's tags were moved by 0.5 s.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest

from trackproc.constants import OMEGA_EARTH
from trackproc.io.passfile import PassTable
from trackproc.models import modifiers as md
from trackproc.models import observation as ob
from trackproc.pipeline.estimate import EstimateOptions, build_problem, estimate
from trackproc.pipeline.simulate import SimulateOptions, simulate

from test_estimate import EOP, GUESS, STATIONS, TRUTH
from test_modifiers import _meas, _trajectory

KINDS = ["range", "range_rate", "doppler", "azimuth", "elevation"]


def _set(t):
    kinds = [KINDS[i % len(KINDS)] for i in range(t.size)]
    return _meas(kinds, t), kinds


@pytest.mark.parametrize("with_acceleration", [False, True])
def test_shifted_samples_are_the_station_later(with_acceleration):
    """``MeasurementSet.shifted(dt)`` is the station at ``t + dt`` (closed form of a turning sphere),
    whether the axis comes from the acceleration or is the default z axis."""
    t = np.linspace(0.0, 600.0, 11)
    meas, kinds = _set(t)
    if with_acceleration:
        meas.a_st = -OMEGA_EARTH ** 2 * meas.r_st * np.array([1.0, 1.0, 0.0])
    dt = np.linspace(-3.0, 3.0, t.size)
    moved, ref = meas.shifted(dt), _meas(kinds, t + dt)
    np.testing.assert_allclose(moved.t_s, t + dt, rtol=0, atol=1e-12)
    np.testing.assert_allclose(moved.r_st, ref.r_st, rtol=0, atol=1e-6)
    np.testing.assert_allclose(moved.v_st, ref.v_st, rtol=0, atol=1e-9)
    np.testing.assert_allclose(moved.gcrf_to_enu, ref.gcrf_to_enu, rtol=0, atol=1e-12)


def test_the_value_is_the_model_at_the_true_time_and_the_partial_its_time_derivative():
    traj = _trajectory()
    t = np.linspace(100.0, 700.0, 25)
    meas, kinds = _set(t)
    bound = md.StationTimeBias("S").bind(meas)
    tau = 0.5
    name = bound.name
    h, jac, _ = ob.evaluate(meas, traj, modifiers=[bound], bias_values={name: tau}, bias_columns={name: 6})
    h_true, _, _ = ob.evaluate(_meas(kinds, t - tau), traj)
    np.testing.assert_allclose(h, h_true, rtol=1e-13, atol=1e-9)
    # the partial against a central difference of the whole model in tau
    eps = 1e-3
    hp, hm = (ob.evaluate(meas, traj, modifiers=[bound], bias_values={name: tau + s})[0] for s in (eps, -eps))
    numeric = np.where(meas.periodic, ob.wrap_pi(hp - hm), hp - hm) / (2 * eps)
    np.testing.assert_allclose(jac[:, 6], numeric, rtol=1e-5, atol=1e-9 * np.abs(numeric).max())
    # ranges: -dρ/dt_r is minus the Doppler range-rate at the true time (closed form)
    rng = np.array(kinds) == "range"
    rr = ob.evaluate(replace(_meas(kinds, t - tau), kind=np.array(["range_rate"] * t.size, dtype=object)), traj)[0]
    np.testing.assert_allclose(jac[rng, 6], -rr[rng], rtol=1e-7)
    # the state columns are those of the model at the true time
    np.testing.assert_allclose(jac[:, :6], ob.evaluate(_meas(kinds, t - tau), traj)[1], rtol=1e-12, atol=1e-12)


def _late(sim, station: str, dt_s: float) -> PassTable:
    """The simulation with ``station``'s time tags ``dt_s`` late (its samples describe ``t - dt``)."""
    frame = sim.frame.copy()
    rows = frame["station"] == station
    frame.loc[rows, "time"] = frame.loc[rows, "time"] + np.timedelta64(int(dt_s * 1e9), "ns")
    return PassTable(frame, sim.meta)


@lru_cache(maxsize=None)
def _day():
    """A day of 3 stations, range (10 m) and range-rate (1 cm/s) every 30 s, no biases."""
    return simulate(TRUTH, STATIONS, SimulateOptions(duration_s=86400.0, step_s=30.0, seed=7,
                                                     kinds=("range", "range_rate"), range_bias_m={}), EOP)


def test_a_half_second_time_tag_offset_is_recovered():
    """KIR's tags 0.5 s late. Without the bias the fit cannot absorb it (orbit off by many sigma,
    residuals far beyond the noise); ``station_time_bias=["KIR"]`` recovers 0.5 s within 3 sigma
    (its sigma a few ms) and the state is within 4 sigma of the truth."""
    sim = _day()
    table = [("sim.parquet", _late(sim, "KIR", 0.5))]
    plain = estimate(table, GUESS, None, EstimateOptions(), EOP)
    z_plain = (plain.solution.values[:6] - sim.truth.rv) / plain.solution.sigma[:6]
    res = estimate(table, GUESS, None, EstimateOptions(station_time_bias=["KIR"]), EOP)
    sol = res.solution
    assert sol.names[6:] == ["time_bias:KIR"]
    tau, sig = sol.values[6], sol.sigma[6]
    z = (sol.values[:6] - sim.truth.rv) / sol.sigma[:6]
    print("plain z", np.round(z_plain, 1), "vf", plain.solution.variance_factor, plain.quality.verdict)
    print("tau", tau, "sigma", sig, "state z", np.round(z, 2), "vf", sol.variance_factor,
          res.quality.verdict)
    assert abs(tau - 0.5) < 3.0 * sig and sig < 0.05, (tau, sig)
    assert np.all(np.abs(z) < 4.0), z
    assert 0.7 < sol.variance_factor < 1.3
    assert res.quality.verdict == "ok"
    # without it: the orbit thousands of sigma off, the variance factor ~1e5, and the verdict says so
    assert np.max(np.abs(z_plain)) > 100.0 and plain.solution.variance_factor > 100.0
    assert plain.quality.verdict != "ok"


def test_build_problem_takes_the_station_time_sigma_as_apriori():
    """The a-priori sigma of ``time_bias:S`` is the station's ``time_sigma_s``; ``--apriori-sigma``
    wins; a station with ``time_sigma_s`` 0 has exact tags (no driver); a named station without
    samples is an input error."""
    from trackproc.errors import InputError

    sim = simulate(TRUTH, STATIONS, SimulateOptions(duration_s=6 * 3600.0, step_s=120.0, seed=1,
                                                    kinds=("range",)), EOP)
    stations = {"KIR": replace(STATIONS["KIR"], time_sigma_s=0.3), "MAD": replace(STATIONS["MAD"], time_sigma_s=0.0),
                "ZHY": STATIONS["ZHY"]}
    tables = [("sim.parquet", PassTable(sim.frame, sim.meta))]
    p = build_problem(tables, GUESS, stations, EstimateOptions(station_time_bias=True), EOP)
    drivers = {d.name: d for d in p.params if d.family == "time_bias"}
    assert set(drivers) == {"time_bias:KIR", "time_bias:ZHY"}
    assert drivers["time_bias:KIR"].apriori_sigma == 0.3 and drivers["time_bias:ZHY"].apriori_sigma is None
    p = build_problem(tables, GUESS, stations, EstimateOptions(station_time_bias=["KIR"],
                                                               apriori_sigma={"time_bias": 1.0}), EOP)
    assert [d.apriori_sigma for d in p.params if d.family == "time_bias"] == [1.0]
    with pytest.raises(InputError, match="--station-time-bias-station"):
        build_problem(tables, GUESS, stations, EstimateOptions(station_time_bias=["XXX"]), EOP)
    # an offset common to all stations is the orbit moved along-track: refused without an a-priori
    with pytest.raises(InputError, match="common to every station"):
        build_problem(tables, GUESS, STATIONS, EstimateOptions(station_time_bias=True), EOP)


def test_every_station_with_a_stated_time_sigma():
    """All three stations' offsets with the stations table's 1 s each: the common part is the
    a-priori's (one cannot tell it from the orbit), so KIR's 0.5 s is shared out; each offset is
    within 3 sigma of the truth, the differences to KIR are recovered sharply, and the state is
    within 4 sigma."""
    sim = _day()
    stations = {k: replace(v, time_sigma_s=1.0) for k, v in STATIONS.items()}
    res = estimate([("sim.parquet", _late(sim, "KIR", 0.5))], GUESS, stations,
                   EstimateOptions(station_time_bias=True), EOP)
    sol = res.solution
    assert sol.names[6:] == ["time_bias:KIR", "time_bias:MAD", "time_bias:ZHY"]
    truth = np.array([0.5, 0.0, 0.0])
    z = (sol.values[6:] - truth) / sol.sigma[6:]
    cov = res.state.covariance
    diff = sol.values[6] - sol.values[7:]
    diff_sigma = np.sqrt(cov[6, 6] + np.diag(cov)[7:] - 2 * cov[6, 7:])
    print("tau", sol.values[6:], "sigma", sol.sigma[6:], "diff", diff, diff_sigma)
    assert np.all(np.abs(z) < 3.0), z
    assert np.all(np.abs(diff - 0.5) < 3.0 * diff_sigma) and np.all(diff_sigma < 0.01), (diff, diff_sigma)
    z_state = (sol.values[:6] - sim.truth.rv) / sol.sigma[:6]
    assert np.all(np.abs(z_state) < 4.0), z_state
