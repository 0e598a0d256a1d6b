"""Frames: GCRF <-> ITRF against ERFA, velocities against finite differences, geodesy hand
cases, azimuth/elevation against erfa.hd2ae, frame bias, and Vallado's TEME example."""

import erfa
import numpy as np
import pytest

from trackproc.constants import WGS84_A
from trackproc.dynamics import frames, geodesy
from trackproc.dynamics import timescales as ts

AS2R = np.pi / (180 * 3600)


def jd(text):
    j1, j2 = ts.datetime64_to_jd_utc(np.datetime64(text))
    return float(j1), float(j2)


def eop_table(dut1=-0.1234, xp=0.1523, yp=0.3011, lod_s=0.0015, pm_rate=0.0008):
    """Tabulated EOP around 2026-03-20 with nonzero UT1-UTC, polar motion and their rates."""
    mjd = np.arange(61117.0, 61124.0)
    k = mjd - mjd[0]
    return ts.eop_from_table(mjd, dut1 - lod_s * k, xp + pm_rate * k, yp - pm_rate * k, source="test table")


def fd4(f, h):
    """Fourth-order central difference of f at 0 with step h."""
    return (-f(2 * h) + 8 * f(h) - 8 * f(-h) + f(-2 * h)) / (12 * h)


# ----------------------------------------------------------------- GCRF <-> ITRF

def test_gcrf_to_itrf_matrix_matches_erfa_c2t06a():
    eop = eop_table()
    j1, j2 = jd("2026-03-20T09:30:00.25")
    dut1, xp, yp = eop.at(j1, j2)
    assert abs(float(xp)) > 0 and abs(float(yp)) > 0 and abs(float(dut1)) > 0
    tt1, tt2 = ts.utc_to_tt(j1, j2)
    u1, u2 = ts.utc_to_ut1(j1, j2, dut1)
    expected = erfa.c2t06a(tt1, tt2, u1, u2, xp, yp)
    rot = frames.earth_rotation(j1, j2, eop)
    assert np.max(np.abs(rot.matrix[0] - expected)) < 1e-15
    r = np.array([3774841.0, -1538034.0, 5924146.0])
    r_itrf, _ = frames.gcrf_to_itrf(r, np.zeros(3), j1, j2, eop)
    assert np.max(np.abs(r_itrf[0] - expected @ r)) < 1e-8


def test_itrf_gcrf_round_trip():
    eop = eop_table()
    t = np.array(["2026-03-20T00:00:00", "2026-03-21T13:14:15.5", "2026-03-22T23:00:00"], dtype="datetime64[ns]")
    j1, j2 = ts.datetime64_to_jd_utc(t)
    rng = np.random.default_rng(3)
    r = rng.normal(size=(3, 3)) * 7e6
    v = rng.normal(size=(3, 3)) * 7e3
    r_i, v_i = frames.gcrf_to_itrf(r, v, j1, j2, eop)
    r_g, v_g = frames.itrf_to_gcrf(r_i, v_i, j1, j2, eop)
    assert np.max(np.abs(r_g - r)) < 1e-8
    assert np.max(np.abs(v_g - v)) < 1e-11


@pytest.mark.parametrize("use_eop", [False, True])
def test_velocity_transform_is_the_derivative_of_the_position_transform(use_eop):
    # includes the Earth-rotation term and the slow rates of precession-nutation, polar motion
    # and UT1 (length of day); without the slow terms the error was 1.1e-5 .. 1.7e-5 m/s
    eop = eop_table() if use_eop else None
    j1, j2 = jd("2026-03-20T09:30:00")
    r_st = geodesy.geodetic_to_itrf(np.radians(48.0), np.radians(35.0), 150.0)

    def station_gcrf(dt):
        return frames.itrf_to_gcrf(r_st, np.zeros(3), j1, j2 + dt / 86400.0, eop)[0][0]

    v_num = fd4(station_gcrf, 2.0)
    v_model = frames.itrf_to_gcrf(r_st, np.zeros(3), j1, j2, eop)[1][0]
    assert np.max(np.abs(v_num - v_model)) < 2e-7

    # a satellite moving in GCRF, seen in ITRF
    r0, v0 = np.array([3774841.0, -1538034.0, 5924146.0]), np.array([-4816.6, 3936.4, 4091.1])

    def sat_itrf(dt):
        return frames.gcrf_to_itrf(r0 + v0 * dt, v0, j1, j2 + dt / 86400.0, eop)[0][0]

    v_num = fd4(sat_itrf, 2.0)
    v_model = frames.gcrf_to_itrf(r0, v0, j1, j2, eop)[1][0]
    assert np.max(np.abs(v_num - v_model)) < 3e-7


def test_several_stations_share_one_earth_orientation_evaluation():
    t = np.array(["2026-03-20T00:00:00", "2026-03-20T06:00:00"], dtype="datetime64[ns]")
    j1, j2 = ts.datetime64_to_jd_utc(t)
    sts = np.array([[6378137.0, 0, 0], [0, 6378137.0, 0]])
    r_many, v_many = frames.itrf_to_gcrf(np.broadcast_to(sts[:, None, :], (2, 2, 3)), np.zeros((2, 2, 3)), j1, j2)
    for s in range(2):
        r_one, v_one = frames.itrf_to_gcrf(np.broadcast_to(sts[s], (2, 3)), np.zeros((2, 3)), j1, j2)
        assert np.array_equal(r_many[s], r_one) and np.array_equal(v_many[s], v_one)


# ----------------------------------------------------------------- geodesy

@pytest.mark.parametrize("lon_deg, expected", [(0.0, (1, 0, 0)), (90.0, (0, 1, 0)), (180.0, (-1, 0, 0))])
def test_station_on_the_equator(lon_deg, expected):
    r = geodesy.geodetic_to_itrf(0.0, np.radians(lon_deg), 0.0)
    assert np.max(np.abs(r - WGS84_A * np.array(expected))) < 1e-6


def test_pole_is_at_the_semi_minor_axis():
    b = WGS84_A * (1 - 1 / 298.257223563)
    r = geodesy.geodetic_to_itrf(np.radians(90.0), 0.0, 0.0)
    assert r[2] == pytest.approx(b, abs=1e-6) and abs(r[0]) < 1e-6


def test_geodetic_round_trip():
    lat, lon, h = np.radians(67.857), np.radians(20.964), 412.5
    back = geodesy.itrf_to_geodetic(geodesy.geodetic_to_itrf(lat, lon, h))
    assert back[0] == pytest.approx(lat, abs=1e-12) and back[1] == pytest.approx(lon, abs=1e-12)
    assert back[2] == pytest.approx(h, abs=1e-6)


def test_point_straight_above_the_station_is_at_elevation_90():
    lat, lon = np.radians(48.0), np.radians(35.0)
    st = geodesy.geodetic_to_itrf(lat, lon, 150.0)
    up = geodesy.enu_matrix(lat, lon)[2]
    _, el, rng = geodesy.enu_to_azel(geodesy.itrf_to_enu(st + 500e3 * up, st, lat, lon))
    assert np.degrees(el) == pytest.approx(90.0, abs=1e-9)
    assert rng == pytest.approx(500e3, abs=1e-6)
    # the geodetic up is the ellipsoid normal: the same point rises from a higher ellipsoidal height
    above = geodesy.geodetic_to_itrf(lat, lon, 500150.0)
    _, el2, _ = geodesy.enu_to_azel(geodesy.itrf_to_enu(above, st, lat, lon))
    assert np.degrees(el2) == pytest.approx(90.0, abs=1e-9)


@pytest.mark.parametrize("axis, az_deg", [(1, 0.0), (0, 90.0)])
def test_due_north_and_due_east_on_the_horizon(axis, az_deg):
    lat, lon = np.radians(-33.0), np.radians(151.0)
    st = geodesy.geodetic_to_itrf(lat, lon, 0.0)
    direction = geodesy.enu_matrix(lat, lon)[axis]
    az, el, _ = geodesy.enu_to_azel(geodesy.itrf_to_enu(st + 1e5 * direction, st, lat, lon))
    # compare on the circle: due north can come out as 360 - 1e-14 deg, which rounds to 360.0
    assert np.degrees(np.angle(np.exp(1j * (az - np.radians(az_deg))))) == pytest.approx(0.0, abs=1e-9)
    assert np.degrees(el) == pytest.approx(0.0, abs=1e-9)


def test_azel_against_erfa_hd2ae():
    rng = np.random.default_rng(11)
    for _ in range(50):
        lat = rng.uniform(-np.pi / 2 + 0.01, np.pi / 2 - 0.01)
        lon = rng.uniform(-np.pi, np.pi)
        st = geodesy.geodetic_to_itrf(lat, lon, rng.uniform(0, 3000))
        d = rng.normal(size=3)
        az, el, _ = geodesy.enu_to_azel(geodesy.itrf_to_enu(st + 1e6 * d, st, lat, lon))
        # hour angle / declination of the topocentric ITRF direction (HA westward from the meridian)
        dec = np.arcsin(d[2] / np.linalg.norm(d))
        ha = lon - np.arctan2(d[1], d[0])
        az_e, el_e = erfa.hd2ae(ha, dec, lat)
        assert el == pytest.approx(el_e, abs=1e-12)
        assert np.angle(np.exp(1j * (az - az_e))) == pytest.approx(0.0, abs=1e-11)


# ----------------------------------------------------------------- EME2000, TEME

def test_eme2000_frame_bias_is_about_23_mas():
    rb = frames.frame_bias_matrix()
    angle = np.arccos(np.clip((np.trace(rb) - 1) / 2, -1, 1)) / AS2R * 1e3
    assert 15.0 < angle < 30.0   # IERS 2010: dα0 = -14.6, ξ0 = -16.6, η0 = -6.8 mas
    r = np.array([42164e3, 0.0, 0.0])
    r_g, _ = frames.eme2000_to_gcrf(r, np.zeros(3))
    shift = np.linalg.norm(r_g - r)
    assert 1.0 < shift < 6.0      # metres at GEO radius
    back, _ = frames.gcrf_to_eme2000(r_g, np.zeros(3))
    assert np.max(np.abs(back - r)) < 1e-8


# Vallado, Crawford, Hujsak & Kelso (2006), "Revisiting Spacetrack Report #3", AIAA 2006-6753,
# TEME example (also Vallado, Fundamentals 4th ed., examples 3-14/3-15): 2004-04-06 07:51:28.386009 UTC
VALLADO_T = "2004-04-06T07:51:28.386009"
VALLADO_TEME_R_KM = np.array([5094.18016210, 6127.64465950, 6380.34453270])
VALLADO_TEME_V_KM_S = np.array([-4.746131487, 0.785818041, 5.531931288])
VALLADO_ITRF_R_KM = np.array([-1033.4793830, 7901.2952754, 6380.3565958])
VALLADO_ITRF_V_KM_S = np.array([-3.225636520, -2.872451450, 5.531924446])
VALLADO_GCRF_R_KM = np.array([5102.508959, 6123.011403, 6378.136925])
VALLADO_GCRF_V_KM_S = np.array([-4.743220156, 0.790536497, 5.533755728])


def vallado_eop():
    mjd = [53100.0, 53102.0]
    return ts.eop_from_table(mjd, [-0.4399619] * 2, [-0.140682] * 2, [0.333309] * 2, source="Vallado 2006")


def test_vallado_2006_teme_to_itrf():
    j1, j2 = jd(VALLADO_T)
    r, v = frames.teme_to_itrf(VALLADO_TEME_R_KM * 1e3, VALLADO_TEME_V_KM_S * 1e3, j1, j2, vallado_eop())
    assert np.max(np.abs(r[0] - VALLADO_ITRF_R_KM * 1e3)) < 0.02       # measured 9 mm
    assert np.max(np.abs(v[0] - VALLADO_ITRF_V_KM_S * 1e3)) < 1e-4     # LOD term omitted: 1e-5 m/s


def test_vallado_2006_teme_to_gcrf():
    j1, j2 = jd(VALLADO_T)
    r, v = frames.teme_to_gcrf(VALLADO_TEME_R_KM * 1e3, VALLADO_TEME_V_KM_S * 1e3, j1, j2, vallado_eop())
    # Vallado's GCRF includes the dX, dY celestial-pole offsets (~0.2 mas, ~1 cm here); we do not
    assert np.max(np.abs(r[0] - VALLADO_GCRF_R_KM * 1e3)) < 0.05       # measured 3 mm
    assert np.max(np.abs(v[0] - VALLADO_GCRF_V_KM_S * 1e3)) < 1e-4


def test_to_gcrf_dispatch_and_unknown_frame():
    j1, j2 = jd("2026-03-20T09:30:00")
    r, v = np.array([7e6, 0.0, 0.0]), np.array([0.0, 7.5e3, 0.0])
    for name in ("GCRF", "gcrf", "ICRF"):
        assert np.array_equal(frames.to_gcrf(name, r, v, j1, j2)[0][0], r)
    for name in ("J2000", "EME2000"):
        assert np.allclose(frames.to_gcrf(name, r, v, j1, j2)[0], frames.eme2000_to_gcrf(r, v)[0], atol=0)
    with pytest.raises(ValueError, match="unknown frame"):
        frames.to_gcrf("B1950", r, v, j1, j2)


def test_quasi_inertial_frame_station_within_a_centimetre_over_a_pass():
    eop = eop_table()
    j1, j2 = jd("2026-03-20T09:30:00")
    q = frames.QuasiInertialFrame.at(j1, j2, eop)
    st = geodesy.geodetic_to_itrf(np.radians(48.0), np.radians(35.0), 150.0)
    t_s = np.linspace(-450.0, 450.0, 7)
    t1, t2 = ts.add_seconds_utc((j1, j2), t_s)
    r_exact, v_exact = frames.itrf_to_gcrf(np.broadcast_to(st, (7, 3)), np.zeros((7, 3)), t1, t2, eop)
    r_q, v_q = q.station(t_s, st)
    r_q_gcrf, v_q_gcrf = q.to_gcrf(r_q, v_q)
    assert np.max(np.linalg.norm(r_q_gcrf - r_exact, axis=1)) < 0.01
    assert np.max(np.linalg.norm(v_q_gcrf - v_exact, axis=1)) < 1e-4
