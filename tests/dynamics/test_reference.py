"""The reference propagator (DOP853, rtol 1e-13) against closed forms and conservation laws."""

import numpy as np
import pytest

from trackproc.constants import J2, MU_EARTH, RE_EARTH
from trackproc.dynamics import frames, reference
from trackproc.dynamics import timescales as ts

R0 = np.array([3774841.0, -1538034.0, 5924146.0])     # seed 004 Table 1 truth (km -> m)
V0 = np.array([-4816.6, 3936.4, 4091.1])


def _stumpff(z):
    if z > 1e-6:
        s = np.sqrt(z)
        return (1 - np.cos(s)) / z, (s - np.sin(s)) / s ** 3
    if z < -1e-6:
        s = np.sqrt(-z)
        return (np.cosh(s) - 1) / -z, (np.sinh(s) - s) / s ** 3
    return 1 / 2 - z / 24 + z * z / 720 - z ** 3 / 40320, 1 / 6 - z / 120 + z * z / 5040 - z ** 3 / 362880


def kepler_universal(r0, v0, t, mu=MU_EARTH):
    """Two-body state at time t (s) by universal variables (Curtis, Orbital Mechanics, alg. 3.3/3.4;
    Newton on the universal Kepler equation). Independent of trackproc.dynamics.kepler."""
    r0, v0 = np.asarray(r0, float), np.asarray(v0, float)
    rn = np.linalg.norm(r0)
    vr = r0 @ v0 / rn
    alpha = 2 / rn - v0 @ v0 / mu
    sq = np.sqrt(mu)
    if alpha > 0:   # reduce whole revolutions so Newton starts close
        period = 2 * np.pi / (sq * alpha ** 1.5)
        revs = np.round(t / period)
        t_red = t - revs * period
    else:
        revs, t_red, period = 0.0, t, 0.0
    chi = sq * abs(alpha) * t_red
    for _ in range(60):
        z = alpha * chi * chi
        c, s = _stumpff(z)
        f = rn * vr / sq * chi * chi * c + (1 - alpha * rn) * chi ** 3 * s + rn * chi - sq * t_red
        df = rn * vr / sq * chi * (1 - z * s) + (1 - alpha * rn) * chi * chi * c + rn
        step = f / df
        chi -= step
        if abs(step) < 1e-13 * max(1.0, abs(chi)):
            break
    z = alpha * chi * chi
    c, s = _stumpff(z)
    f = 1 - chi * chi / rn * c
    g = t_red - chi ** 3 / sq * s
    r = f * r0 + g * v0
    r1 = np.linalg.norm(r)
    fdot = sq / (r1 * rn) * (alpha * chi ** 3 * s - chi)
    gdot = 1 - chi * chi / r1 * c
    return r, fdot * r0 + gdot * v0


def test_kepler_universal_helper_agrees_with_dynamics_kepler_when_present():
    kepler = pytest.importorskip("trackproc.dynamics.kepler")
    for t in (600.0, -3000.0, 86400.0):
        r, v = kepler_universal(R0, V0, t)
        other = kepler.propagate(np.r_[R0, V0], np.array([t]))[0]
        assert np.max(np.abs(other[:3] - r)) < 1e-4 and np.max(np.abs(other[3:] - v)) < 1e-7


def test_kepler_universal_two_body_dop853_within_a_millimetre_over_a_day_of_leo():
    t = np.arange(0.0, 86400.0 + 1, 10.0)
    r, v = reference.propagate(R0, V0, t, MU_EARTH, 0.0)
    pick = np.r_[np.arange(0, t.size, 137), t.size - 1]
    err_r = max(np.linalg.norm(r[i] - kepler_universal(R0, V0, t[i])[0]) for i in pick)
    err_v = max(np.linalg.norm(v[i] - kepler_universal(R0, V0, t[i])[1]) for i in pick)
    assert err_r < 1e-3      # measured ~1.2e-5 m after a day
    assert err_v < 1e-6


def test_backward_and_unsorted_times():
    t = np.array([600.0, -1200.0, 0.0, 600.0, -30.0, 3600.0])
    r, v = reference.propagate(R0, V0, t, MU_EARTH, 0.0)
    assert np.array_equal(r[2], R0) and np.array_equal(v[2], V0)
    assert np.array_equal(r[0], r[3])
    for i, ti in enumerate(t):
        rk, vk = kepler_universal(R0, V0, ti)
        assert np.linalg.norm(r[i] - rk) < 1e-4 and np.linalg.norm(v[i] - vk) < 1e-7
    r, v = reference.propagate(R0, V0, [0.0], MU_EARTH, J2)
    assert np.array_equal(r[0], R0) and np.array_equal(v[0], V0)


def test_outputs_are_not_interpolated_between_steps():
    # a node requested alone and among many must agree to the integrator's local error
    r1, _ = reference.propagate(R0, V0, [1234.5], MU_EARTH, J2)
    r2, _ = reference.propagate(R0, V0, np.linspace(0, 5000, 501).tolist() + [1234.5], MU_EARTH, J2)
    assert np.linalg.norm(r1[0] - r2[-1]) < 1e-5


def _j2_potential(r, mu=MU_EARTH, j2=J2, re=RE_EARTH):
    rn = np.linalg.norm(r, axis=-1)
    s = r[..., 2] / rn
    return mu / rn * (1 - j2 * (re / rn) ** 2 * (1.5 * s * s - 0.5))


def test_j2_acceleration_is_the_gradient_of_the_potential():
    r = np.array([4.1e6, -3.3e6, 4.9e6])
    h = 100.0
    u = _j2_potential
    grad = np.array([(-u(r + 2 * h * e) + 8 * u(r + h * e) - 8 * u(r - h * e) + u(r - 2 * h * e)) / (12 * h)
                     for e in np.eye(3)])
    acc = reference.acceleration(r, MU_EARTH, J2, RE_EARTH)
    assert np.max(np.abs(grad - acc)) < 1e-9 * np.linalg.norm(acc)


def test_jerk_is_the_time_derivative_of_the_acceleration():
    r, v = R0, V0
    for j2 in (0.0, J2):
        def acc(dt, j2=j2):
            return reference.acceleration(r + v * dt, MU_EARTH, j2, RE_EARTH)
        h = 0.5
        num = (-acc(2 * h) + 8 * acc(h) - 8 * acc(-h) + acc(-2 * h)) / (12 * h)
        assert np.max(np.abs(num - reference.jerk(r, v, MU_EARTH, j2, RE_EARTH))) < 1e-12


def test_j2_conserves_energy_and_polar_angular_momentum_over_a_day():
    t = np.linspace(0.0, 86400.0, 97)
    r, v = reference.propagate(R0, V0, t, MU_EARTH, J2)
    energy = 0.5 * np.sum(v * v, 1) - _j2_potential(r)
    hz = r[:, 0] * v[:, 1] - r[:, 1] * v[:, 0]
    assert np.max(np.abs(energy - energy[0])) / abs(energy[0]) < 1e-11
    assert np.max(np.abs(hz - hz[0])) / abs(hz[0]) < 1e-11
    # and J2 really acts: the node regresses at the secular rate -3/2 n J2 (Re/p)^2 cos i
    h = np.cross(r, v)
    node0, node1 = np.arctan2(h[0, 0], -h[0, 1]), np.arctan2(h[-1, 0], -h[-1, 1])
    rn, v2 = np.linalg.norm(R0), V0 @ V0
    a = 1 / (2 / rn - v2 / MU_EARTH)
    p = (h[0] @ h[0]) / MU_EARTH
    rate = -1.5 * np.sqrt(MU_EARTH / a ** 3) * J2 * (RE_EARTH / p) ** 2 * h[0, 2] / np.linalg.norm(h[0])
    assert (node1 - node0) == pytest.approx(rate * 86400.0, rel=0.05)


def test_propagate_gcrf_applies_j2_about_the_rotation_axis():
    j1, j2d = ts.datetime64_to_jd_utc(np.datetime64("2026-03-20T09:30:00"))
    q = frames.QuasiInertialFrame.at(float(j1), float(j2d)).q
    t = np.linspace(0, 20000, 11)
    r, v = reference.propagate_gcrf(R0, V0, t, q, "j2")
    axis = q[2]       # the CIP in GCRF
    hk = np.cross(r, v) @ axis
    assert np.max(np.abs(hk - hk[0])) / abs(hk[0]) < 1e-11
    # about GCRF z instead, h_z would not be conserved (precession since J2000: ~0.1 deg)
    hz = np.cross(r, v)[:, 2]
    assert np.max(np.abs(hz - hz[0])) / abs(hz[0]) > 1e-7
    acc, jerk = reference.acceleration_gcrf(r, v, q, "j2")
    assert np.allclose(acc, reference.acceleration(r @ q.T, MU_EARTH, J2, RE_EARTH) @ q, rtol=0, atol=1e-15)
    assert jerk.shape == r.shape


def test_force_parameters():
    assert reference.force_parameters("two-body")[1] == 0.0
    assert reference.force_parameters("j2")[1] == J2
    with pytest.raises(ValueError):
        reference.force_parameters("egm96")
