"""Universal-variable Kepler propagation: invariants, conics, and against scipy DOP853."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from trackproc.constants import MU_EARTH
from trackproc.dynamics import kepler
from trackproc.errors import ProcessingError

MU = MU_EARTH
#: seed 004 Table 1 "truth" state (km -> m), a near-circular LEO orbit.
LEO = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1])
RP = 6878137.0


def _molniya(e=0.7, tilt=1.1):
    vp = math.sqrt(MU * (1 + e) / RP)
    return np.array([RP, 0.0, 0.0, 0.0, vp * math.cos(tilt), vp * math.sin(tilt)])


def _hyperbola():
    vp = math.sqrt(MU * (1 + 2.5) / RP)
    return np.array([0.0, RP, 0.0, -vp, 0.0, 300.0])


def _parabola():
    return np.array([RP, 0.0, 0.0, 0.0, math.sqrt(2 * MU / RP), 0.0])


CONICS = {"leo": LEO, "molniya": _molniya(), "hyperbola": _hyperbola(), "parabola": _parabola()}


def _rhs(t, y):
    r = y[:3]
    return np.concatenate([y[3:], -MU * r / np.linalg.norm(r) ** 3])


def _dop853(s0, t):
    """DOP853 at rtol 1e-13 on both sides of t = 0."""
    out = np.empty((t.size, 6))
    for side in (t >= 0, t < 0):
        if not side.any():
            continue
        ts = t[side]
        order = np.argsort(np.abs(ts))
        sol = solve_ivp(_rhs, (0.0, ts[order][-1]), s0, method="DOP853", rtol=1e-13, atol=1e-9,
                        t_eval=ts[order])
        res = np.empty((ts.size, 6))
        res[order] = sol.y.T
        out[side] = res
    return out


def test_stumpff_closed_forms_and_limits():
    z = np.array([-50.0, -10.0 - 1e-9, -10.0, -3.0, -1e-8, 0.0, 1e-8, 2.0, 9.99, 10.0, 40.0])
    c2, c3 = kepler.stumpff(z)
    for zi, a2, a3 in zip(z, c2, c3):
        if zi > 0:
            s = math.sqrt(zi)
            r2, r3 = (1 - math.cos(s)) / zi, (s - math.sin(s)) / s ** 3
        elif zi < 0:
            s = math.sqrt(-zi)
            r2, r3 = (math.cosh(s) - 1) / -zi, (math.sinh(s) - s) / s ** 3
        else:
            r2, r3 = 0.5, 1.0 / 6.0
        tol = 1e-14 if abs(zi) > 1.0 else 1e-7 if zi != 0 else 1e-16  # closed forms cancel near 0
        assert a2 == pytest.approx(r2, rel=tol)
        assert a3 == pytest.approx(r3, rel=tol)
    # continuity across the series / closed-form switch at |z| = 10
    a, b = kepler.stumpff(np.array([10.0 - 1e-12, 10.0 + 1e-12]))
    assert a[0] == pytest.approx(a[1], rel=1e-12) and b[0] == pytest.approx(b[1], rel=1e-12)


@pytest.mark.parametrize("name", list(CONICS))
def test_kepler_universal_conserves_energy_and_angular_momentum(name):
    s0 = CONICS[name]
    t = np.linspace(-40000.0, 40000.0, 81)
    st = kepler.propagate(s0, t)
    e = kepler.specific_energy(st)
    h = kepler.angular_momentum(st)
    v2 = np.sum(s0[3:] ** 2)
    assert np.ptp(e) <= 1e-14 * (v2 / 2)
    assert np.abs(h - h[40]).max() <= 1e-14 * np.linalg.norm(h[40])


@pytest.mark.parametrize("name", list(CONICS))
def test_kepler_universal_against_dop853(name):
    s0 = CONICS[name]
    t = np.linspace(-15000.0, 15000.0, 31)
    ref = _dop853(s0, t)
    st = kepler.propagate(s0, t)
    # DOP853 at rtol 1e-13 itself is good to ~1e-4 m over these arcs
    assert np.abs(st[:, :3] - ref[:, :3]).max() < 1e-3
    assert np.abs(st[:, 3:] - ref[:, 3:]).max() < 1e-6


def test_kepler_universal_period_return_and_apoapsis():
    s0 = _molniya(e=0.7)
    per = float(kepler.period(s0))
    a = RP / (1 - 0.7)
    assert per == pytest.approx(2 * math.pi * math.sqrt(a ** 3 / MU), rel=1e-14)
    half, full, many = kepler.propagate(s0, np.array([per / 2, per, 37 * per]))
    assert np.linalg.norm(half[:3]) == pytest.approx(a * 1.7, rel=1e-13)       # apoapsis
    assert np.abs(full - s0)[:3].max() < 1e-6 and np.abs(many - s0)[:3].max() < 1e-5


@pytest.mark.parametrize("name", list(CONICS))
def test_kepler_universal_round_trip(name):
    s0 = CONICS[name]
    for dt in (1234.5, -20000.0, 86400.0):
        s1 = kepler.propagate(s0, dt)
        back = kepler.propagate(s1, -dt)
        # rounding of the far state (|r1| up to 1e9 m) limits how well it can come back
        assert np.abs(back[:3] - s0[:3]).max() < 1e-6 + 1e-14 * np.linalg.norm(s1[:3])
        assert np.abs(back[3:] - s0[3:]).max() < 1e-12 * np.linalg.norm(s0[3:])


def test_kepler_hyperbola_asymptotic_speed():
    s0 = _hyperbola()
    vinf2 = 2 * kepler.specific_energy(s0)
    far = kepler.propagate(s0, 3.0e7)
    assert np.linalg.norm(far[:3]) > 1e11
    v2 = np.sum(far[3:] ** 2)
    assert v2 == pytest.approx(vinf2 + 2 * MU / np.linalg.norm(far[:3]), rel=1e-12)


def test_kepler_shapes_and_zero_time():
    assert kepler.propagate(LEO, 10.0).shape == (6,)
    assert kepler.propagate(LEO, [0.0, 1.0, 2.0]).shape == (3, 6)
    batch = np.stack([LEO, _molniya(), _hyperbola()])
    out = kepler.propagate(batch, np.array([0.0, 100.0]))
    assert out.shape == (3, 2, 6)
    np.testing.assert_array_equal(out[:, 0], batch)
    np.testing.assert_allclose(out[1, 1], kepler.propagate(_molniya(), 100.0), rtol=1e-15)
    with pytest.raises(ValueError):
        kepler.propagate(LEO[:5], 1.0)


def test_kepler_non_convergence_is_an_error():
    with pytest.raises(ProcessingError):
        kepler.universal_anomaly(RP, 3000.0, 0.5 / RP, 5.0e3, MU, max_iter=1)
