"""Osculating classical elements (issue 16: elements beside the Cartesian state in every state
output): Vallado's published example, an independent perifocal construction, and Kepler's
equation through the universal-variable propagator."""

import math

import numpy as np
import pytest

from trackproc.constants import MU_EARTH
from trackproc.dynamics.kepler import classical_elements, propagate


def test_vallado_example_2_5():
    # Vallado (2013), Example 2-5 (RV2COE): mu = 398600.4418 km^3/s^2
    el = classical_elements(np.array([6524.834, 6862.875, 6448.296]) * 1e3,
                            np.array([4.901327, 5.533756, -1.976341]) * 1e3, 398600.4418e9)
    assert el["a_m"] / 1e3 == pytest.approx(36127.343, abs=0.02)
    assert el["e"] == pytest.approx(0.832853, abs=2e-6)
    assert el["i_deg"] == pytest.approx(87.870, abs=1e-3)
    assert el["raan_deg"] == pytest.approx(227.898, abs=1e-3)
    assert el["argp_deg"] == pytest.approx(53.38, abs=0.01)
    assert el["true_anomaly_deg"] == pytest.approx(92.335, abs=1e-3)


def _perifocal_state(a, e, i, raan, argp, nu, mu=MU_EARTH):
    """An independent construction: the perifocal position and velocity rotated by R3(-raan) R1(-i) R3(-argp)."""
    p = a * (1 - e * e)
    r_pf = np.array([p * math.cos(nu), p * math.sin(nu), 0.0]) / (1 + e * math.cos(nu))
    v_pf = math.sqrt(mu / p) * np.array([-math.sin(nu), e + math.cos(nu), 0.0])

    def r3(t):
        return np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])

    def r1(t):
        return np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])

    q = r3(raan) @ r1(i) @ r3(argp)
    return q @ r_pf, q @ v_pf


@pytest.mark.parametrize("a,e,i,raan,argp,nu", [
    (7.0e6, 0.01, 98.0, 30.0, 40.0, 50.0),
    (2.6e7, 0.7, 63.4, 200.0, 270.0, 170.0),
    (4.2164e7, 0.0002, 0.5, 10.0, 300.0, 359.0),
])
def test_round_trip_of_an_independent_construction(a, e, i, raan, argp, nu):
    r, v = _perifocal_state(a, e, *np.radians([i, raan, argp, nu]))
    el = classical_elements(r, v)
    assert el["a_m"] == pytest.approx(a, rel=1e-12)
    assert el["e"] == pytest.approx(e, abs=1e-12)
    for key, want in (("i_deg", i), ("raan_deg", raan), ("argp_deg", argp), ("true_anomaly_deg", nu),
                      ("arg_latitude_deg", (argp + nu) % 360)):
        assert (el[key] - want + 180) % 360 - 180 == pytest.approx(0, abs=1e-8), key


def test_circular_orbit_has_argument_of_latitude_only():
    r, v = _perifocal_state(7.0e6, 0.0, *np.radians([51.6, 80.0, 0.0, 123.0]))
    el = classical_elements(r, v)
    assert el["argp_deg"] is None and el["true_anomaly_deg"] is None
    assert el["arg_latitude_deg"] == pytest.approx(123.0, abs=1e-9)


def test_mean_anomaly_advances_at_the_mean_motion():
    r, v = _perifocal_state(7.5e6, 0.1, *np.radians([45.0, 10.0, 20.0, 30.0]))
    el0 = classical_elements(r, v)
    dt = 1234.5
    s1 = propagate(np.concatenate([r, v]), dt)
    el1 = classical_elements(s1[:3], s1[3:])
    n = math.sqrt(MU_EARTH / el0["a_m"] ** 3)
    advance = el1["mean_anomaly_deg"] - el0["mean_anomaly_deg"] - math.degrees(n * dt)
    assert (advance + 180) % 360 - 180 == pytest.approx(0, abs=1e-7)
    assert el0["period_s"] == pytest.approx(2 * math.pi / n)
