"""Measurement models: light time, range-rate as the derivative of the light-time range, Doppler
sign, two-way legs, azimuth/elevation against ERFA."""

import erfa
import numpy as np
import pytest
from test_reference import kepler_universal

from trackproc.constants import C_LIGHT, MU_EARTH
from trackproc.dynamics import frames, geodesy, reference
from trackproc.dynamics import timescales as ts
from trackproc.models import measurements as mm
from oracles import measurements_oracle as oracle

R0 = np.array([3774841.0, -1538034.0, 5924146.0])
V0 = np.array([-4816.6, 3936.4, 4091.1])
LAT, LON, H = np.radians(48.0), np.radians(35.0), 150.0
EPOCH = ts.datetime64_to_jd_utc(np.datetime64("2026-03-20T09:30:00"))
ST_ITRF = geodesy.geodetic_to_itrf(LAT, LON, H)
EOP = ts.eop_from_table(np.arange(61117.0, 61124.0), 0.1 - 0.0015 * np.arange(7), [0.15] * 7, [0.3] * 7, "test")


def satellite(t):
    """Two-body truth (closed form) at t seconds from EPOCH, with acceleration and jerk."""
    r, v = kepler_universal(R0, V0, t)
    return r, v, reference.acceleration(r, MU_EARTH), reference.jerk(r, v, MU_EARTH)


def observe(t, mode="one-way", model="doppler", eop=EOP):
    j1, j2 = ts.add_seconds_utc(EPOCH, np.atleast_1d(t))
    st = mm.station_gcrf(ST_ITRF, j1, j2, eop)
    r, v, a, j = satellite(float(t))
    return mm.observables(r[None], v[None], a[None], j[None], st.r, st.v, st.a, st.gcrf_to_itrf, LAT, LON,
                          carrier_hz=2.2e9, mode=mode, range_rate_model=model)


def fd4(f, h):
    return (-f(2 * h) + 8 * f(h) - 8 * f(-h) + f(-2 * h)) / (12 * h)


# pass times (s from EPOCH): rising, highest (~22 deg), setting, low, below the horizon
TIMES = [-300.0, -70.0, 0.0, 300.0, 3000.0]


@pytest.mark.parametrize("mode", ["one-way", "two-way"])
@pytest.mark.parametrize("t", TIMES)
def test_range_rate_is_the_derivative_of_the_light_time_range(t, mode):
    o = observe(t, mode)
    numeric = fd4(lambda dt: observe(t + dt, mode).range_m[0], 0.5)
    assert abs(numeric - o.range_rate_m_s[0]) < 1e-6


@pytest.mark.parametrize("t", TIMES)
def test_instantaneous_model_drops_the_light_time_factor(t):
    doppler = observe(t, "one-way", "doppler")
    inst = observe(t, "one-way", "instantaneous")
    j1, j2 = ts.add_seconds_utc(EPOCH, np.atleast_1d(t))
    st = mm.station_gcrf(ST_ITRF, j1, j2, EOP)
    r, v, a, j = satellite(t)
    leg = mm.light_time_down(r[None], v[None], a[None], j[None], st.r)
    factor = 1 + leg.u[0] @ leg.state[:, 3:][0] / C_LIGHT
    assert inst.range_rate_m_s[0] == pytest.approx(doppler.range_rate_m_s[0] * factor, abs=1e-9)
    assert abs(inst.range_rate_m_s[0] - doppler.range_rate_m_s[0]) < 0.2     # README: up to ~0.15 m/s in LEO


@pytest.mark.parametrize("t", [0.0, 300.0, 3000.0])
def test_light_time_range_against_brute_force_fixed_point(t):
    # independent: a second (closed-form) propagator evaluation at each emission-time guess
    j1, j2 = ts.add_seconds_utc(EPOCH, np.atleast_1d(t))
    st = mm.station_gcrf(ST_ITRF, j1, j2, EOP)
    tau = 0.0
    for _ in range(20):
        r_e, _ = kepler_universal(R0, V0, t - tau)
        tau = np.linalg.norm(r_e - st.r[0]) / C_LIGHT
    rho_brute = np.linalg.norm(kepler_universal(R0, V0, t - tau)[0] - st.r[0])
    o = observe(t)
    assert abs(o.range_m[0] - rho_brute) < 1e-6            # sub-micrometre in practice
    assert abs(o.light_time_s[0] - tau) < 1e-12
    # and the light time matters: it moves the range by tens of metres in LEO
    r_now = satellite(t)[0]
    assert abs(np.linalg.norm(r_now - st.r[0]) - rho_brute) > 1.0


def test_two_way_up_leg_against_brute_force():
    t = 200.0
    j1, j2 = ts.add_seconds_utc(EPOCH, np.atleast_1d(t))
    st_r = mm.station_gcrf(ST_ITRF, j1, j2, EOP).r[0]
    tau_d = 0.0
    for _ in range(20):
        tau_d = np.linalg.norm(kepler_universal(R0, V0, t - tau_d)[0] - st_r) / C_LIGHT
    r_b = kepler_universal(R0, V0, t - tau_d)[0]
    tau_u = tau_d
    for _ in range(20):
        k1, k2 = ts.add_seconds_utc(EPOCH, np.atleast_1d(t - tau_d - tau_u))
        st_t = mm.station_gcrf(ST_ITRF, k1, k2, EOP).r[0]
        tau_u = np.linalg.norm(r_b - st_t) / C_LIGHT
    expected = 0.5 * C_LIGHT * (tau_d + tau_u)
    o = observe(t, "two-way")
    assert abs(o.range_m[0] - expected) < 1e-6
    assert o.light_time_s[0] == pytest.approx(tau_d + tau_u, abs=1e-12)


def test_doppler_sign_receding_is_negative_doppler_positive_range_rate():
    setting = observe(420.0)      # late in the pass: range grows
    rising = observe(-300.0)     # approaching: range shrinks
    assert setting.range_rate_m_s[0] > 0 and setting.doppler_hz[0] < 0
    assert rising.range_rate_m_s[0] < 0 and rising.doppler_hz[0] > 0
    assert setting.doppler_hz[0] == pytest.approx(-2.2e9 * setting.range_rate_m_s[0] / C_LIGHT, rel=1e-15)
    two = observe(420.0, "two-way")
    assert two.doppler_hz[0] == pytest.approx(-2 * 2.2e9 * two.range_rate_m_s[0] / C_LIGHT, rel=1e-15)


def test_doppler_offset_drift_and_inverse():
    rr = np.array([-3000.0, 0.0, 2500.0])
    f = mm.doppler_hz(rr, 2.2e9, "one-way", offset_hz=12.5, drift_hz_s=0.01, t_s=np.array([0.0, 10.0, 20.0]))
    assert np.allclose(f - np.array([12.5, 12.6, 12.7]), -2.2e9 * rr / C_LIGHT, rtol=0, atol=1e-9)
    assert np.allclose(mm.range_rate_from_doppler(mm.doppler_hz(rr, 2.2e9, "two-way"), 2.2e9, "two-way"), rr)


@pytest.mark.parametrize("t", [0.0, 150.0, 300.0, 450.0])
def test_azel_against_erfa_hd2ae(t):
    j1, j2 = ts.add_seconds_utc(EPOCH, np.atleast_1d(t))
    st = mm.station_gcrf(ST_ITRF, j1, j2, EOP)
    r, v, a, j = satellite(t)
    leg = mm.light_time_down(r[None], v[None], a[None], j[None], st.r)
    d_itrf = frames.gcrf_to_itrf(leg.state[:, :3][0] - st.r[0], np.zeros(3), j1, j2, EOP)[0][0]
    dec = np.arcsin(d_itrf[2] / np.linalg.norm(d_itrf))
    ha = LON - np.arctan2(d_itrf[1], d_itrf[0])
    az_e, el_e = erfa.hd2ae(ha, dec, LAT)
    o = observe(t)
    assert o.elevation_rad[0] == pytest.approx(el_e, abs=1e-11)
    assert np.angle(np.exp(1j * (o.azimuth_rad[0] - az_e))) == pytest.approx(0.0, abs=1e-11)


def test_station_state_in_gcrf():
    t = np.array([0.0, 100.0, 200.0])
    j1, j2 = ts.add_seconds_utc(EPOCH, t)
    st = mm.station_gcrf(ST_ITRF, j1, j2, EOP)
    r, v = frames.itrf_to_gcrf(np.broadcast_to(ST_ITRF, (3, 3)), np.zeros((3, 3)), j1, j2, EOP)
    assert np.array_equal(st.r, r) and np.array_equal(st.v, v)
    assert np.linalg.norm(st.v[0]) == pytest.approx(frames.OMEGA_ERA * np.hypot(*ST_ITRF[:2]), rel=1e-6)
    # acceleration: derivative of the velocity (centripetal, |a| = ω² ρ)
    h = 1.0
    k1, k2 = ts.add_seconds_utc(EPOCH, np.array([-h, h]))
    vv = mm.station_gcrf(ST_ITRF, k1, k2, EOP).v
    assert np.max(np.abs((vv[1] - vv[0]) / (2 * h) - st.a[0])) < 1e-8
    # several stations at once: (S, N, 3)
    many = mm.station_gcrf(np.stack([ST_ITRF, -ST_ITRF]), j1, j2, EOP)
    assert many.r.shape == (2, 3, 3) and np.array_equal(many.r[0], st.r)


def test_light_time_iteration_converges_to_tolerance():
    j1, j2 = ts.add_seconds_utc(EPOCH, np.array([0.0]))
    st = mm.station_gcrf(ST_ITRF, j1, j2, EOP)
    r, v, a, j = satellite(0.0)
    leg = mm.light_time_down(r[None], v[None], a[None], j[None], st.r)
    assert abs(C_LIGHT * leg.tau_s[0] - leg.rho_m[0]) < 1e-12 * C_LIGHT
    with pytest.raises(ValueError):
        mm.range_rate_value(leg.state[:, :3], leg.state[:, 3:], st.r, st.v, "orekit")


@pytest.mark.parametrize("model", ["doppler", "instantaneous"])
@pytest.mark.parametrize("mode", ["one-way", "two-way"])
def test_simulator_equals_the_independent_oracle(mode, model):
    """The simulator's observables (the shared light-time solver and observables) against the
    independent implementation kept in tests/oracles, over a pass and two stations at once."""
    t = np.linspace(-400.0, 400.0, 9)
    j1, j2 = ts.add_seconds_utc(EPOCH, t)
    st_itrf = np.stack([ST_ITRF, geodesy.geodetic_to_itrf(np.radians(52.0), np.radians(30.0), 10.0)])
    lat, lon = np.array([[LAT], [np.radians(52.0)]]), np.array([[LON], [np.radians(30.0)]])
    st = mm.station_gcrf(st_itrf, j1, j2, EOP)
    sat = [satellite(x) for x in t]
    r, v, a, j = (np.array([s[k] for s in sat]) for k in range(4))
    ours = mm.observables(r, v, a, j, st.r, st.v, st.a, st.gcrf_to_itrf, lat, lon, carrier_hz=2.2e9, mode=mode,
                          range_rate_model=model)
    ref = oracle.observables(r, v, a, j, st.r, st.v, st.a, st.gcrf_to_itrf, lat, lon, carrier_hz=2.2e9, mode=mode,
                             range_rate_model=model)
    for name in ("range_m", "range_rate_m_s", "doppler_hz", "elevation_rad", "azimuth_rad", "light_time_s"):
        np.testing.assert_allclose(getattr(ours, name), getattr(ref, name), rtol=1e-13, atol=1e-12, err_msg=name)
    # and the two implementations really differ from a geometric (no light time) model
    geometric = np.linalg.norm(r - st.r, axis=-1)
    assert np.max(np.abs(ref.range_m - geometric)) > 1.0


#: An Earth-orientation table with UT1-UTC, xp and yp all moving (length of day 1.5 ms, polar motion
#: 2 and 1 mas a day), as IERS columns: (MJD, UT1-UTC s, xp arcsec, yp arcsec).
EOP_MOVING = (np.arange(61117.0, 61124.0), 0.1 - 0.0015 * np.arange(7), 0.15 + 0.002 * np.arange(7),
              0.3 - 0.001 * np.arange(7))


def test_stations_equal_the_independent_oracle():
    """Geodetic -> ITRF -> GCRF stations with their velocity, acceleration and rotation against the
    oracle's own (Vallado's closed-form site vector, ``erfa.c2t06a`` at every date, rates by
    seven-point differences), for five stations (both hemispheres, the equator at the date line,
    near the pole, 3 km up) over 12 h."""
    lat = np.radians([48.0, 67.8, -33.9, 0.0, 89.5])
    lon = np.radians([35.0, 20.9, -70.7, 179.9, -120.0])
    h = np.array([150.0, 400.0, 2500.0, 0.0, 3000.0])
    j1, j2 = ts.add_seconds_utc(EPOCH, np.linspace(-6 * 3600.0, 6 * 3600.0, 13))
    r_itrf = geodesy.geodetic_to_itrf(lat, lon, h)
    np.testing.assert_allclose(r_itrf, oracle.geodetic_to_ecef(lat, lon, h), rtol=0, atol=1e-8)
    ours = mm.station_gcrf(r_itrf, j1, j2, ts.eop_from_table(*EOP_MOVING, "test"))
    ref = oracle.station_gcrf(lat, lon, h, j1, j2, EOP_MOVING)
    np.testing.assert_allclose(ours.gcrf_to_itrf, ref.gcrf_to_itrf, rtol=0, atol=1e-15)
    # measured: 3e-9 m (rounding), 1e-9 m/s (the oracle's differences, DIFF_STEP_S)
    np.testing.assert_allclose(ours.r, ref.r, rtol=0, atol=1e-8)
    np.testing.assert_allclose(ours.v, ref.v, rtol=0, atol=5e-9)
    # trackproc's acceleration is the centripetal ω × v about the mid-span axis (nominal ω): 2.5e-9
    # m/s² from the exact one, i.e. 1e-11 m over a 0.1 s round trip
    np.testing.assert_allclose(ours.a, ref.a, rtol=0, atol=1e-8)
    # what the tolerances can see: the length of day's share of the velocity (UT1-UTC held at its
    # value at the middle date, where the positions then agree) and polar motion's of the position
    mjd_mid = j1[6] - 2400000.5 + j2[6]
    held = (EOP_MOVING[0], np.full(7, np.interp(mjd_mid, EOP_MOVING[0], EOP_MOVING[1])), *EOP_MOVING[2:])
    no_lod = oracle.station_gcrf(lat, lon, h, j1[6:7], j2[6:7], held)
    assert np.abs(no_lod.r[:, 0] - ref.r[:, 6]).max() < 1e-6 and np.abs(no_lod.v[:, 0] - ref.v[:, 6]).max() > 5e-6
    no_pm = oracle.station_gcrf(lat, lon, h, j1, j2, (*EOP_MOVING[:2], np.zeros(7), np.zeros(7)))
    assert np.abs(no_pm.r - ref.r).max() > 1.0
