"""Measurement spectra in the image domain (seed 004 eqs. 7-13): the station rotation in closed
form, range and range-rate with one-way light time against the foundation simulator's model,
range-rate as the derivative of the light-time range, partials against central finite
differences, and the size of the frozen-frame error."""

from __future__ import annotations

import numpy as np
import pytest

from trackproc.constants import C_LIGHT
from trackproc.dynamics import frames, geodesy, propagator, reference
from trackproc.dynamics import measurement_spectra as ms
from trackproc.dynamics import spectra as sp
from trackproc.dynamics import timescales as ts
from trackproc.models import measurements as mm

R0 = np.array([3774841.0, -1538034.0, 5924146.0])
V0 = np.array([-4816.6, 3936.4, 4091.1])
EPOCH = np.datetime64("2026-03-20T09:30:00", "ns")
JD = tuple(float(x) for x in ts.datetime64_to_jd_utc(EPOCH))
#: a tabulated EOP with a 1.5 ms length-of-day excess and 0.3 arcsec of polar motion
EOP = ts.eop_from_table(np.arange(61117.0, 61124.0), 0.1 - 0.0015 * np.arange(7), [0.15] * 7, [0.3] * 7, "test")
LOW = (np.radians(48.0), np.radians(35.0), 150.0)        # a 22-deg pass centred on the epoch
PASS = np.linspace(-300.0, 300.0, 601)


def _overhead_station():
    """A station right under the satellite at the epoch: a pass through the zenith."""
    r_itrf, _ = frames.gcrf_to_itrf(R0, V0, *JD, EOP)
    lat, lon, _ = geodesy.itrf_to_geodetic(r_itrf[0])
    return float(lat), float(lon), 0.0


HIGH = _overhead_station()


def _setup(site, t, *, force="j2", stm=True, frozen=False, eop=EOP, r0=R0, v0=V0):
    traj = propagator.propagate(r0, v0, EPOCH, t, force=force, eop=eop, stm=stm)
    lat, lon, h = site
    st = ms.StationModel.build(geodesy.geodetic_to_itrf(lat, lon, h), lat, lon, traj.epoch_jd_utc, traj.frame.q,
                               np.min(t), np.max(t), eop=eop, frozen=frozen)
    return traj, st


def _simulator(site, t, model, *, force="j2", eop=EOP, r0=R0, v0=V0):
    """The foundation's model, as trackproc simulate runs it: DOP853 orbit, IAU 2006/2000A
    station, light-time Newton iteration (models/measurements.py)."""
    lat, lon, h = site
    q = frames.QuasiInertialFrame.at(*JD, eop).q
    r, v = reference.propagate_gcrf(r0, v0, t, q, force)
    a, j = reference.acceleration_gcrf(r, v, q, force)
    j1, j2 = ts.add_seconds_utc(JD, t)
    trk = mm.station_gcrf(geodesy.geodetic_to_itrf(lat, lon, h), j1, j2, eop)
    return mm.observables(r, v, a, j, trk.r, trk.v, trk.a, trk.gcrf_to_itrf, lat, lon, carrier_hz=2.2e9,
                          range_rate_model=model)


def _angle_diff(a, b):
    return np.abs(np.angle(np.exp(1j * (a - b))))


# -- the image-domain building blocks ------------------------------------------------------

@pytest.mark.parametrize("theta,omega", [(0.3, 7.292115e-5), (5.9, -1.3), (2.0, 0.7)])
def test_rotation_spectra_closed_form_equals_seed004_eq9_recurrence(theta, omega):
    cs, sn = ms.rotation_spectra(theta, omega, 24)
    s_rec, c_rec = sp.sin_cos(np.r_[theta, omega, np.zeros(22)])
    assert np.allclose(cs, c_rec, rtol=1e-13, atol=1e-300)
    assert np.allclose(sn, s_rec, rtol=1e-13, atol=1e-300)
    tau = 0.37
    assert sp.evaluate(cs, tau) == pytest.approx(np.cos(theta + omega * tau), abs=1e-15)


def test_product_shift_and_derivative_matrices():
    rng = np.random.default_rng(1)
    u, v = rng.normal(size=(2, 3, 12))
    assert np.allclose(u[:, None, :] @ ms.product_matrix(v)[:, :, :], sp.cauchy(u, v)[:, None, :])
    # M(u) M(v) = M(u*v): truncated series form a commutative algebra
    assert np.allclose(ms.product_matrix(u) @ ms.product_matrix(v), ms.product_matrix(sp.cauchy(u, v)))
    # re-expansion about t* + delta keeps the polynomial
    shifted = (u[:, None, :] @ ms.shift_matrix(0.8, 12))[:, 0]
    for tau in (-0.5, 0.0, 0.3):
        assert np.allclose(sp.evaluate(shifted, tau), sp.evaluate(u, 0.8 + tau), rtol=1e-13)
    d = ms.derivative_matrix(12)
    assert np.allclose((u @ d)[:, :-1], sp.derivative(u))


def test_sqrt_and_reciprocal_rules_match_the_spectra_module():
    d2 = sp.cauchy(np.array([[3.0, 0.4, -0.2, 0.05, 0.0, 0.0]]), np.array([[3.0, 0.4, -0.2, 0.05, 0.0, 0.0]]))
    assert np.allclose(ms.series_sqrt(d2), sp.sqrt(d2), rtol=1e-15)
    assert np.allclose(ms.series_reciprocal(d2), sp.quotient(sp.constant(1.0, 6), d2), rtol=1e-14)


# -- the station ---------------------------------------------------------------------------

def test_frozen_station_is_the_quasi_inertial_frame_station():
    eop = ts.EarthOrientation.constant(0.1)          # ERA rate exactly OMEGA_ERA
    frame = frames.QuasiInertialFrame.at(*JD, eop)
    r_itrf = geodesy.geodetic_to_itrf(*LOW)
    st = ms.StationModel.build(r_itrf, LOW[0], LOW[1], JD, frame.q, -600, 600, eop=eop, frozen=True)
    t = np.array([-600.0, 0.0, 123.4, 600.0])
    r, v = st.state(t)
    r_ref, v_ref = frame.station(t, r_itrf)
    assert np.abs(r - r_ref).max() < 1e-8
    assert np.abs(v - v_ref).max() < 1e-11


def test_station_model_against_iau2006_over_a_day():
    # the full model (ERA exact and linear per segment, precession-nutation and polar motion
    # interpolated) against ERFA at every time; and the seed paper's frozen model's error
    r_itrf = geodesy.geodetic_to_itrf(*LOW)
    fr = propagator.reference_frame(*JD, EOP)
    t = np.array([-3600.0, 60.0, 300.0, 900.0, 3600.0, 21600.0, 86400.0])
    full = ms.StationModel.build(r_itrf, LOW[0], LOW[1], JD, fr.q, t.min(), t.max(), eop=EOP)
    frozen = ms.StationModel.build(r_itrf, LOW[0], LOW[1], JD, fr.q, t.min(), t.max(), eop=EOP, frozen=True)
    j1, j2 = ts.add_seconds_utc(JD, t)
    exact = mm.station_gcrf(r_itrf, j1, j2, EOP)
    r_ex, v_ex = exact.r @ fr.q.T, exact.v @ fr.q.T
    r, v = full.state(t)
    assert np.linalg.norm(r - r_ex, axis=1).max() < 1e-6
    assert np.linalg.norm(v - v_ex, axis=1).max() < 1e-8
    rf, vf = frozen.state(t)
    err = np.linalg.norm(rf - r_ex, axis=1)
    # frozen precession-nutation drifts 0.15 arcsec a day: ~3.4 mm after 5 min, ~1 cm after
    # 15 min, ~1.3 m after a day at the station; the missing dQ/dt term is 1.1e-5 m/s
    assert 2e-3 < err[2] < 5e-3 and 5e-3 < err[3] < 2e-2 and 0.5 < err[-1] < 3.0
    assert 5e-6 < np.linalg.norm(vf - v_ex, axis=1).min() < 1e-4


def test_station_spectra_are_the_taylor_series_of_the_station():
    _, st = _setup(LOW, PASS, stm=False)
    spec = st.spectra(np.array([100.0]), 26)[0]
    tau = np.array([-40.0, -5.0, 0.0, 17.0, 40.0])
    r_ref, v_ref = st.state(100.0 + tau)
    # ERFA's era00 resolves the angle to ~2e-14 rad (the ulp of 0.0027 * days since J2000):
    # 1.4e-7 m at the Earth's surface, the noise floor of any per-time station evaluation
    assert np.abs(sp.evaluate(spec, tau).T - r_ref).max() < 1e-6
    assert np.abs(sp.evaluate(spec, tau, derivative=1).T - v_ref).max() < 1e-10


# -- range and range-rate against the foundation simulator --------------------------------

@pytest.mark.parametrize("site", [LOW, HIGH], ids=["22deg", "zenith"])
@pytest.mark.parametrize("model", ["doppler", "instantaneous"])
def test_against_foundation_simulator(site, model):
    traj, st = _setup(site, PASS)
    pred = ms.predict(traj, st, PASS, range_rate_model=model)
    ref = _simulator(site, PASS, model)
    assert np.abs(pred.range_m - ref.range_m).max() < 1e-6
    assert np.abs(pred.range_rate_m_s - ref.range_rate_m_s).max() < 1e-6
    assert np.abs(pred.elevation_rad - ref.elevation_rad).max() < 1e-7
    ok = ref.elevation_rad < np.radians(89.0)            # azimuth is undefined at the zenith
    assert _angle_diff(pred.azimuth_rad[ok], ref.azimuth_rad[ok]).max() < 1e-7
    assert np.abs(pred.light_time_s - ref.light_time_s).max() < 1e-14
    assert pred.segments.iterations <= 4
    if site is HIGH:
        assert np.degrees(ref.elevation_rad.max()) > 85.0


def test_geostationary_light_time_against_simulator():
    # 0.12 s of light time: the Taylor shift r(t - T) needs its higher terms
    a = 42164.2e3
    r0, v0 = np.array([a, 0.0, 0.0]), np.array([0.0, np.sqrt(3.986004418e14 / a), 0.0])
    t = np.linspace(0.0, 3600.0, 61)
    site = (np.radians(10.0), np.radians(30.0), 0.0)
    traj, st = _setup(site, t, force="two-body", r0=r0, v0=v0)
    pred = ms.predict(traj, st, t)
    ref = _simulator(site, t, "doppler", force="two-body", r0=r0, v0=v0)
    assert pred.light_time_s.min() > 0.11
    assert np.abs(pred.range_m - ref.range_m).max() < 1e-6
    assert np.abs(pred.range_rate_m_s - ref.range_rate_m_s).max() < 1e-6


@pytest.mark.parametrize("site", [LOW, HIGH], ids=["22deg", "zenith"])
def test_range_rate_is_the_derivative_of_the_light_time_range(site):
    # the derivative rule on the light-time range spectrum = d(range)/d(reception time)
    t = np.linspace(-280.0, 280.0, 29)
    traj, st = _setup(site, PASS, stm=False)
    pred = ms.predict(traj, st, t)
    h = 0.5

    def rng(dt):
        return ms.predict(traj, st, t + dt).range_m

    numeric = (-rng(2 * h) + 8 * rng(h) - 8 * rng(-h) + rng(-2 * h)) / (12 * h)
    assert np.abs(numeric - pred.range_rate_m_s).max() < 1e-6
    # and of the simulator's (independently computed) light-time range
    sim = [_simulator(site, t + d, "doppler").range_m for d in (2 * h, h, -h, -2 * h)]
    numeric_sim = (-sim[0] + 8 * sim[1] - 8 * sim[2] + sim[3]) / (12 * h)
    assert np.abs(numeric_sim - pred.range_rate_m_s).max() < 1e-6


def test_models_differ_by_the_light_time_factor():
    traj, st = _setup(LOW, PASS, stm=False)
    dop = ms.predict(traj, st, PASS, range_rate_model="doppler")
    inst = ms.predict(traj, st, PASS, range_rate_model="instantaneous")
    diff = np.abs(inst.range_rate_m_s - dop.range_rate_m_s)
    assert 0.01 < diff.max() < 0.2                    # README: up to ~0.15 m/s in LEO


def test_without_light_time_is_the_seed004_geometry():
    traj, st = _setup(LOW, PASS, stm=False)
    pred = ms.predict(traj, st, PASS, light_time=False)
    sat = traj.state(PASS, frame="quasi-inertial")
    r_st, v_st = st.state(PASS)
    d = sat[:, :3] - r_st
    rng = np.linalg.norm(d, axis=1)
    assert np.abs(pred.range_m - rng).max() < 1e-6
    assert np.abs(pred.range_rate_m_s - np.einsum("ni,ni->n", d, sat[:, 3:] - v_st) / rng).max() < 1e-8
    with_lt = ms.predict(traj, st, PASS)
    assert np.abs(with_lt.range_m - pred.range_m).max() > 1.0          # light time: tens of metres


# -- partials -------------------------------------------------------------------------------

@pytest.mark.parametrize("model", ["doppler", "instantaneous"])
@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_partials_against_central_finite_differences(model, force):
    t = np.linspace(-300.0, 300.0, 61)
    traj, st = _setup(HIGH, t, force=force)
    pred = ms.predict(traj, st, t, range_rate_model=model)
    steps = np.array([10.0] * 3 + [0.01] * 3)
    fd_r, fd_rr = np.zeros((t.size, 6)), np.zeros((t.size, 6))
    x0 = np.r_[R0, V0]
    for k in range(6):
        out = []
        for sign in (1.0, -1.0):
            x = x0.copy()
            x[k] += sign * steps[k]
            tr = propagator.propagate(x[:3], x[3:], EPOCH, t, force=force, eop=EOP, frame=traj.frame)
            out.append(ms.predict(tr, st, t, range_rate_model=model))
        fd_r[:, k] = (out[0].range_m - out[1].range_m) / (2 * steps[k])
        fd_rr[:, k] = (out[0].range_rate_m_s - out[1].range_rate_m_s) / (2 * steps[k])
    rel_r = np.abs(pred.d_range_d_state - fd_r).max(axis=0) / np.abs(fd_r).max(axis=0)
    rel_rr = np.abs(pred.d_range_rate_d_state - fd_rr).max(axis=0) / np.abs(fd_rr).max(axis=0)
    assert rel_r.max() < 1e-6
    assert rel_rr.max() < 1e-6


def test_range_partial_is_the_light_time_corrected_projection():
    # closed form at the samples: dD/dx0 = u . dr_sat(t_e)/dx0 / (1 + u . v_sat(t_e) / c)
    t = np.linspace(-200.0, 200.0, 9)
    traj, st = _setup(LOW, np.r_[-201.0, t])         # emission times precede t = -200 s
    pred = ms.predict(traj, st, t)
    t_e = t - pred.light_time_s
    phi = traj.stm(t_e)                               # GCRF
    sat = traj.state(t_e)
    u_qi = pred.rho_qi / pred.range_m[:, None]
    u = u_qi @ traj.frame.q                           # to GCRF
    expected = np.einsum("ni,nij->nj", u, phi[:, :3, :]) / (1 + np.einsum("ni,ni->n", u, sat[:, 3:]) / C_LIGHT)[:, None]
    assert np.abs(pred.d_range_d_state - expected).max() < 1e-9


# -- segments, ordering and errors --------------------------------------------------------

def test_segments_converge_and_unsorted_times_give_the_same_values():
    traj, st = _setup(HIGH, PASS)
    pred = ms.predict(traj, st, PASS)
    seg = pred.segments
    assert np.all(seg.truncation_m() <= traj.tol * np.maximum(np.abs(seg.range[:, 0]), 1.0))
    assert np.all(seg.half_width_s < 0.5 * seg.range[:, 0] / 7000.0)      # within rho/|v_rel| / 2
    rng = np.random.default_rng(3)
    perm = rng.permutation(PASS.size)
    again = ms.predict(traj, st, np.r_[PASS[perm], PASS[:3]])
    assert np.allclose(again.range_m[:PASS.size], pred.range_m[perm], rtol=0, atol=1e-7)
    assert np.allclose(again.d_range_rate_d_state[:PASS.size], pred.d_range_rate_d_state[perm], atol=1e-12)
    assert np.array_equal(again.range_m[PASS.size:], again.range_m[[np.flatnonzero(perm == i)[0]
                                                                      for i in range(3)]])


def test_predict_input_errors():
    traj, st = _setup(LOW, PASS, stm=False)
    with pytest.raises(ValueError, match="range-rate model"):
        ms.predict(traj, st, PASS, range_rate_model="orekit")
    with pytest.raises(ValueError, match="stm=True"):
        ms.predict(traj, st, PASS, partials=True)
    with pytest.raises(ValueError, match="outside the propagated interval"):
        ms.predict(traj, st, np.array([0.0, 400.0]))
    assert ms.predict(traj, st, np.array([12.5])).range_m.shape == (1,)


def test_frozen_frame_error_over_a_pass():
    # the seed paper's model (precession-nutation and polar motion frozen at the reference
    # epoch, the pass centre here) against the full model over a 10-minute pass
    traj, full = _setup(LOW, PASS, stm=False)
    _, frozen = _setup(LOW, PASS, stm=False, frozen=True)
    a = ms.predict(traj, full, PASS)
    b = ms.predict(traj, frozen, PASS)
    dr = np.abs(a.range_m - b.range_m).max()
    drr = np.abs(a.range_rate_m_s - b.range_rate_m_s).max()
    assert 1e-3 < dr < 1e-2                       # millimetres over +-5 min (measured 3.3 mm)
    assert 1e-6 < drr < 5e-5                      # ~1e-5 m/s: the missing dQ/dt term
