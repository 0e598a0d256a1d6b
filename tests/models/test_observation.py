"""Estimation measurement models: every partial against central finite differences, the light
time against the simulator's, and the bias modifiers."""

import numpy as np
import pytest

from trackproc.constants import C_LIGHT, OMEGA_EARTH
from trackproc.dynamics import propagator
from oracles import measurements_oracle as mm  # the independent implementation
from trackproc.models import observation as ob

RNG = np.random.default_rng(11)
EPOCH = np.datetime64("2026-03-20T09:30:00")
STATE0 = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1])


def _geometry(n=20):
    r_e = RNG.normal(size=(n, 3)) * 4e6 + [7e6, 0, 0]
    v_e = RNG.normal(size=(n, 3)) * 4e3
    r_st = RNG.normal(size=(n, 3)) * 2e6 + [5e6, 1e6, 0]
    v_st = RNG.normal(size=(n, 3)) * 300.0
    return r_e, v_e, r_st, v_st


def _fd(fun, x, h):
    """Central differences of fun (N,) -> (N,) over the last axis of x (N, 3): (N, 3)."""
    out = np.empty(x.shape)
    for k in range(3):
        dx = np.zeros_like(x)
        dx[:, k] = h
        out[:, k] = (fun(x + dx) - fun(x - dx)) / (2 * h)
    return out


@pytest.mark.parametrize("model", ["doppler", "instantaneous"])
def test_range_rate_partials_match_central_differences(model):
    r_e, v_e, r_st, v_st = _geometry()
    rr, d_r, d_v = ob.range_rate_partials(r_e, v_e, r_st, v_st, model)
    np.testing.assert_allclose(rr, ob.range_rate_value(r_e, v_e, r_st, v_st, model), rtol=1e-14)
    fd_r = _fd(lambda r: ob.range_rate_value(r, v_e, r_st, v_st, model), r_e, 10.0)
    fd_v = _fd(lambda v: ob.range_rate_value(r_e, v, r_st, v_st, model), v_e, 1.0)
    np.testing.assert_allclose(d_r, fd_r, rtol=1e-6, atol=1e-11)       # |d_r| ~ 1e-3 /s
    np.testing.assert_allclose(d_v, fd_v, rtol=1e-8, atol=1e-10)       # |d_v| ~ 1


def test_range_rate_equals_the_simulators_models():
    r_e, v_e, r_st, v_st = _geometry()
    d = r_e - r_st
    rho = np.linalg.norm(d, axis=1)
    leg = mm.Leg(rho_m=rho, tau_s=rho / C_LIGHT, u=d / rho[:, None], r_sat=r_e, v_sat=v_e, r_st=r_st, v_st=v_st)
    for model in ("doppler", "instantaneous"):
        np.testing.assert_allclose(ob.range_rate_value(r_e, v_e, r_st, v_st, model),
                                   mm.range_rate_down(leg, model), rtol=1e-14, atol=1e-12)


def test_range_partial():
    r_e, _, r_st, _ = _geometry()
    rho, u, d_r = ob.range_partials(r_e, r_st)
    fd = _fd(lambda r: np.linalg.norm(r - r_st, axis=1), r_e, 10.0)
    np.testing.assert_allclose(d_r, fd, rtol=1e-7, atol=1e-9)            # unit vector; round-off 1e-10


def _rotations(n):
    q, _ = np.linalg.qr(RNG.normal(size=(n, 3, 3)))
    return q * np.sign(np.linalg.det(q))[:, None, None]


def test_azel_partials_match_central_differences_and_the_simulator():
    r_e, _, r_st, _ = _geometry()
    m = _rotations(len(r_e))
    d = r_e - r_st
    az, el, d_az, d_el = ob.azel_partials(d, m)
    fd_az = _fd(lambda x: ob.wrap_pi(ob.azel_value(x, m)[0] - az) + az, d, 1.0)
    fd_el = _fd(lambda x: ob.azel_value(x, m)[1], d, 1.0)
    np.testing.assert_allclose(d_az, fd_az, rtol=1e-6, atol=1e-13)
    np.testing.assert_allclose(d_el, fd_el, rtol=1e-6, atol=1e-13)
    # the simulator's azel with E = identity-at-lat/lon 0: use the ENU matrix explicitly
    from trackproc.dynamics import geodesy

    lat, lon = 0.6, 0.3
    enu = geodesy.enu_matrix(lat, lon)
    az_s, el_s = mm.azel(d, m, lat, lon)
    az2, el2 = ob.azel_value(d, enu @ m)
    np.testing.assert_allclose(az2, az_s, atol=1e-14)
    np.testing.assert_allclose(el2, el_s, atol=1e-14)


# ----------------------------------------------------------------------------- through light time

def _Trajectory(state0, t_end=3000.0, force="j2"):
    """The propagation façade (GCRF, J2 about the axis of the epoch) with the STM."""
    return propagator.propagate(state0[:3], state0[3:], EPOCH, [-1.0, t_end], force=force,
                                stm=True).raise_for_outcome()


def _stations(t):
    """A station on a rotating sphere (inertial position and velocity at t)."""
    ang = OMEGA_EARTH * t
    r0 = np.array([4.0e6, -1.0e6, 4.8e6])
    c, s = np.cos(ang), np.sin(ang)
    r = np.stack([c * r0[0] - s * r0[1], s * r0[0] + c * r0[1], np.full_like(t, r0[2])], -1)
    v = OMEGA_EARTH * np.stack([-r[:, 1], r[:, 0], np.zeros_like(t)], -1)
    return r, v


def _meas(kinds, t):
    r_st, v_st = _stations(t)
    n = t.size
    return ob.MeasurementSet(t_s=t, kind=np.array(kinds, dtype=object), station=np.full(n, "S", dtype=object),
                             pass_id=np.full(n, "S-001", dtype=object), observed=np.zeros(n), sigma=np.ones(n),
                             r_st=r_st, v_st=v_st, gcrf_to_enu=_rotations(n), carrier_hz=np.full(n, 2.2e9))


def test_light_time_matches_the_simulators_iteration():
    traj = _Trajectory(STATE0)
    t = np.linspace(100.0, 900.0, 9)
    r_st, v_st = _stations(t)
    geo = ob.solve_light_time(traj, t, r_st)
    s = traj.state(t)
    a = traj.state(t, derivative=1)[:, 3:]
    j = traj.state(t, derivative=2)[:, 3:]
    leg = mm.light_time_down(s[:, :3], s[:, 3:], a, j, r_st, v_st)
    np.testing.assert_allclose(geo.tau_s, leg.tau_s, rtol=0, atol=1e-13)
    np.testing.assert_allclose(geo.rho_m, leg.rho_m, rtol=0, atol=1e-6)
    np.testing.assert_allclose(geo.rho_m, C_LIGHT * geo.tau_s, rtol=1e-14)
    assert geo.iterations <= 4


def test_light_time_from_an_earlier_evaluations_light_times_is_the_same_solution():
    """A start from the light times of an orbit 2 km away (what ``Problem`` hands the next
    evaluation) converges to the independent iteration's light times as the cold start does,
    with one trajectory evaluation fewer."""
    t = np.linspace(100.0, 900.0, 9)
    r_st, v_st = _stations(t)
    nearby = ob.solve_light_time(_Trajectory(STATE0 + np.r_[2000.0, -1000.0, 500.0, 1.0, 0.0, -1.0]), t, r_st)
    traj = _Trajectory(STATE0)
    s = traj.state(t)
    leg = mm.light_time_down(s[:, :3], s[:, 3:], traj.state(t, derivative=1)[:, 3:],
                             traj.state(t, derivative=2)[:, 3:], r_st, v_st)
    counts = []
    for tau0 in (None, nearby.tau_s):
        calls = []

        class Counted:
            def state(self, tt, derivative=0):
                calls.append(1)
                return traj.state(tt, derivative=derivative)

        geo = ob.solve_light_time(Counted(), t, r_st, tau0=tau0)
        np.testing.assert_allclose(geo.tau_s, leg.tau_s, rtol=0, atol=1e-13)
        assert np.array_equal(geo.state, traj.state(geo.t_e_s))   # the state at the τ returned, kept or not
        counts.append(len(calls))
    assert np.max(np.abs(nearby.tau_s - leg.tau_s)) > 1e-6       # a start that needs the iteration
    assert counts[1] == counts[0] - 1


@pytest.mark.parametrize("model", ["doppler", "instantaneous"])
def test_partials_through_light_time_match_central_differences_of_the_initial_state(model):
    """The whole chain: propagation STM, light time (eq. 6), geometry, every kind."""
    kinds = ["range", "range_rate", "doppler", "azimuth", "elevation"] * 3
    t = np.linspace(200.0, 2500.0, len(kinds))
    meas = _meas(kinds, t)
    traj = _Trajectory(STATE0)
    value, jac, _ = ob.evaluate(meas, traj, range_rate_model=model)
    steps = np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3])
    fd = np.empty_like(jac)
    for k in range(6):
        d = np.zeros(6)
        d[k] = steps[k]
        vp = ob.evaluate(meas, _Trajectory(STATE0 + d), range_rate_model=model)[0]
        vm = ob.evaluate(meas, _Trajectory(STATE0 - d), range_rate_model=model)[0]
        diff = vp - vm
        diff = np.where(meas.periodic, ob.wrap_pi(diff), diff)
        fd[:, k] = diff / (2 * steps[k])
    scale = np.abs(fd).max(axis=1, keepdims=True)
    np.testing.assert_allclose(jac / scale, fd / scale, rtol=0, atol=2e-7)


def test_light_time_factor_in_the_range_partial():
    """Without the 1/(1 + û·v/c) factor the range partial would be off by ~|v|/c ≈ 2e-5."""
    t = np.array([600.0])
    meas = _meas(["range"], t)
    traj = _Trajectory(STATE0)
    _, jac, geo = ob.evaluate(meas, traj)
    naive = geo.u[0] @ traj.stm(geo.t_e_s)[0, :3, :]
    factor = 1.0 + geo.u[0] @ geo.state[0, 3:] / C_LIGHT
    np.testing.assert_allclose(jac[0], naive / factor, rtol=1e-12)
    assert abs(factor - 1.0) > 1e-6


def test_bias_modifiers_rows_and_coefficients():
    t = np.arange(10.0)
    kinds = ["range", "doppler", "range_rate", "azimuth", "elevation"] * 2
    meas = _meas(kinds, t)
    meas.station = np.array(["A"] * 5 + ["B"] * 5, dtype=object)
    meas.pass_id = np.array(["A-001"] * 5 + ["B-001"] * 5, dtype=object)
    names = ["x", "range_bias:A", "doppler_offset:B-001", "doppler_drift:A", "az_bias:B", "el_bias:A"]
    mods = {m.name: m for m in ob.bias_modifiers(meas, names, epochs={"doppler_drift:A": 1.0})}
    assert "x" not in mods
    assert mods["range_bias:A"].rows.tolist() == [0]
    assert mods["doppler_offset:B-001"].rows.tolist() == [6, 7]
    np.testing.assert_allclose(mods["doppler_offset:B-001"].coefficients(), [1.0, -C_LIGHT / 2.2e9])
    np.testing.assert_allclose(mods["doppler_drift:A"].coefficients(), [0.0, -C_LIGHT / 2.2e9 * 1.0])
    assert mods["az_bias:B"].rows.tolist() == [8] and mods["el_bias:A"].rows.tolist() == [4]
    with pytest.raises(ValueError, match="acts on no measurement"):
        ob.bias_modifiers(meas, ["range_bias:C"])
    meas.carrier_hz[:] = np.nan
    with pytest.raises(ValueError, match="carrier"):
        ob.bias_modifiers(meas, ["doppler_offset:A"])


def test_bias_values_and_columns_in_evaluate():
    t = np.linspace(300.0, 400.0, 6)
    meas = _meas(["range", "doppler", "range_rate", "azimuth", "elevation", "range"], t)
    traj = _Trajectory(STATE0)
    base, _, _ = ob.evaluate(meas, traj)
    names = ["range_bias:S", "doppler_offset:S-001", "az_bias:S", "el_bias:S"]
    mods = ob.bias_modifiers(meas, names)
    vals = {"range_bias:S": 100.0, "doppler_offset:S-001": 3.0, "az_bias:S": 1e-3, "el_bias:S": 2e-3}
    cols = {n: 6 + i for i, n in enumerate(names)}
    value, jac, _ = ob.evaluate(meas, traj, modifiers=mods, bias_values=vals, bias_columns=cols)
    np.testing.assert_allclose(value - base, [100.0, 3.0, -3.0 * C_LIGHT / 2.2e9, 1e-3, 2e-3, 100.0], rtol=1e-12)
    assert jac.shape == (6, 10)
    np.testing.assert_allclose(jac[:, 6], [1, 0, 0, 0, 0, 1])
    np.testing.assert_allclose(jac[:, 7], [0, 1, -C_LIGHT / 2.2e9, 0, 0, 0])


def test_values_alone_are_the_values_with_partials_and_kinds_follow_the_kind_array():
    """``partials=False`` gives the same values bit for bit (without the emission state's
    derivative, read only by the partials); the kept kind masks follow a new ``kind`` array."""
    t = np.linspace(100.0, 900.0, 12)
    meas = _meas(["doppler"] * 12, t)
    traj = _Trajectory(STATE0)
    h, jac, geo = ob.evaluate(meas, traj, n_columns=6)
    h0, jac0, geo0 = ob.evaluate(meas, _Trajectory(STATE0), n_columns=6, partials=False)
    assert np.array_equal(h, h0) and jac0 is None and geo0.state_dot is None
    assert np.array_equal(geo.state_dot, traj.state(geo.t_e_s, derivative=1))
    mixed = _meas(["doppler", "range"] * 6, t)
    hm = ob.evaluate(mixed, traj, n_columns=6)[0]
    assert np.array_equal(hm[::2], h[::2]) and np.allclose(hm[1::2], geo.rho_m[1::2], rtol=0, atol=0)
    meas.kind = np.array(["range"] * 12, dtype=object)
    assert meas.is_kind("range").all() and not meas.is_kind("doppler").any()
    assert np.array_equal(ob.evaluate(meas, traj, n_columns=6)[0], geo.rho_m)
