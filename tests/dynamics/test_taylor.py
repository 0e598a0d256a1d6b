"""Adaptive Taylor integrator: recurrences, accuracy against Kepler and DOP853, dense output,
outcomes, batch mode, and the state transition matrix against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from trackproc.constants import J2, MU_EARTH, RE_EARTH
from trackproc.dynamics import kepler
from trackproc.dynamics import spectra as sp
from trackproc.dynamics import taylor, taylor_series
from trackproc.dynamics.taylor import Outcome, propagate
from trackproc.errors import ProcessingError

#: seed 004 Table 1 "truth" state (km -> m): near-circular LEO, |r| = 7191 km.
LEO = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1])
#: an eccentric orbit (e ~ 0.1, perigee 6878 km), inclined 63 deg.
ECC = np.array([6878137.0, 0.0, 0.0, 0.0, 3630.0, 7126.0])
DAY = 86400.0
MM = 1e-3


def _rhs(force):
    def f(t, y):
        return np.concatenate([y[3:], taylor.acceleration(y[:3], force=force)])
    return f


# -- the P-model recurrences --------------------------------------------------------------

def _reference_spectrum(state, p, force):
    """Position spectra (3, p+2) built from the generic rules of the spectra module:
    X(K+2) = A(K)/((K+1)(K+2)), A from cauchy/power on the first K+1 coefficients."""
    n = p + 2
    x = np.zeros((3, n))
    x[:, 0], x[:, 1] = state[:3], state[3:]
    k2 = -1.5 * J2 * MU_EARTH * RE_EARTH ** 2
    for k in range(p):
        xs = x[:, :k + 1]
        s = sum(sp.cauchy(xs[i], xs[i]) for i in range(3))
        acc = -MU_EARTH * sp.cauchy(xs, sp.power(s, -1.5))
        if force == "j2":
            w5, w7 = sp.power(s, -2.5), sp.power(s, -3.5)
            t = sp.cauchy(sp.cauchy(xs[2], xs[2]), w7)
            hxy = k2 * (w5 - 5.0 * t)
            hz = hxy + 2.0 * k2 * w5
            acc = acc + np.stack([sp.cauchy(xs[0], hxy), sp.cauchy(xs[1], hxy),
                                  sp.cauchy(xs[2], hz)])
        x[:, k + 2] = acc[:, k] / ((k + 1) * (k + 2))
    return x


@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_p_model_seed000_eq14_matches_generic_spectrum_rules(force):
    p = 16
    ref = _reference_spectrum(ECC, p, force)
    r0, v0 = ECC[None, :3], ECC[None, 3:]
    kj2 = -1.5 * J2 * MU_EARTH * RE_EARTH ** 2 if force == "j2" else 0.0
    scale = np.abs(ref).max(axis=0)
    for kernel in (taylor_series.series_state, taylor_series.series_state_single):
        got = kernel(r0, v0, p, MU_EARTH, kj2)[0]
        assert np.all(np.abs(got - ref) <= 1e-12 * scale), kernel.__name__
    # the dual kernel's value part is the same spectrum
    dual = taylor_series.series_dual(r0, v0, np.zeros((1, 3, 1)), np.zeros((1, 3, 1)), p,
                               MU_EARTH, kj2, None)[0, :, 0]
    assert np.all(np.abs(dual - ref) <= 1e-12 * scale)


@pytest.mark.parametrize("force", ["two-body", "j2"])
@pytest.mark.parametrize("state", [LEO, ECC])
def test_variational_fast_path_equals_dual_kernel(force, state):
    """dX(K)/dp by forward-mode dual arithmetic (seed 004 eqs. 19-21) and by the
    variational recurrence of the one-trajectory kernel are the same numbers."""
    rng = np.random.default_rng(11)
    dr, dv = rng.normal(size=(1, 3, 7)), rng.normal(size=(1, 3, 7)) * 1e3
    kj2 = -1.5 * J2 * MU_EARTH * RE_EARTH ** 2 if force == "j2" else 0.0
    args = (state[None, :3], state[None, 3:], dr, dv, 24, MU_EARTH, kj2, 7)
    a = taylor_series.series_dual(*args)
    b = taylor_series.series_var_single(*args)
    hp = 600.0 ** np.arange(26)                       # compare as they are used: at h = 600 s
    assert (np.abs((a - b) * hp).sum(-1) / np.abs(a * hp).sum(-1)).max() < 1e-14


def test_import_stays_light():
    """First result within 50 ms of import: the engine must not pull in scipy or pandas."""
    import subprocess
    import sys
    code = ("import sys, trackproc.dynamics.taylor, trackproc.dynamics.spectra, "
            "trackproc.dynamics.kepler; "
            "print(sorted(m for m in ('scipy', 'pandas', 'typer') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_second_coefficient_is_half_the_acceleration(force):
    x = taylor_series.series_state_single(LEO[None, :3], LEO[None, 3:], 20, MU_EARTH,
                                    -1.5 * J2 * MU_EARTH * RE_EARTH ** 2 if force == "j2" else 0.0)
    acc = taylor.acceleration(LEO[:3], force=force)
    np.testing.assert_allclose(2.0 * x[0, :, 2], acc, rtol=1e-14)


def test_j2_acceleration_formula():
    # on the equator, radial, magnitude mu/r^2 (1 + 3/2 J2 (Re/r)^2)
    r = 7.0e6
    a = taylor.acceleration(np.array([r, 0.0, 0.0]))
    assert a[0] == pytest.approx(-MU_EARTH / r ** 2 * (1 + 1.5 * J2 * (RE_EARTH / r) ** 2),
                                 rel=1e-15)
    # over the pole: mu/r^2 (1 - 3 J2 (Re/r)^2)
    a = taylor.acceleration(np.array([0.0, 0.0, r]))
    assert a[2] == pytest.approx(-MU_EARTH / r ** 2 * (1 - 3.0 * J2 * (RE_EARTH / r) ** 2),
                                 rel=1e-15)


def test_default_order_from_tolerance():
    assert taylor.default_order(1e-15) == 24
    assert taylor.default_order(1e-9) == 14
    assert propagate(LEO, 0.0, 10.0).order == 24


# -- accuracy (targets of issue 3; not timed) ---------------------------------------------

def test_two_body_one_day_against_kepler_universal_within_1mm():
    res = propagate(LEO, 0.0, DAY, force="two-body")
    assert res.outcome is Outcome.SUCCESS
    t = np.linspace(0.0, DAY, 1441)
    err = np.linalg.norm(res.state(t)[:, :3] - kepler.propagate(LEO, t)[:, :3], axis=1)
    assert err.max() < 1.0 * MM                                  # measured: ~1e-6 m
    verr = np.linalg.norm(res.state(t)[:, 3:] - kepler.propagate(LEO, t)[:, 3:], axis=1)
    assert verr.max() < 1e-6


def test_two_body_eccentric_one_day_against_kepler_universal():
    res = propagate(ECC, 0.0, DAY, force="two-body")
    t = np.linspace(0.0, DAY, 1441)
    err = np.linalg.norm(res.state(t)[:, :3] - kepler.propagate(ECC, t)[:, :3], axis=1)
    assert err.max() < 1.0 * MM


def test_pass_600s_tol_1e15_within_1e6_m_of_kepler():
    res = propagate(LEO, 0.0, 600.0, force="two-body", tol=1e-15)
    t = np.linspace(0.0, 600.0, 601)
    err = np.linalg.norm(res.state(t)[:, :3] - kepler.propagate(LEO, t)[:, :3], axis=1)
    assert err.max() <= 1e-6


@pytest.mark.slow
def test_j2_one_day_against_dop853_within_1cm():
    t = np.linspace(0.0, DAY, 721)
    sol = solve_ivp(_rhs("j2"), (0.0, DAY), LEO, method="DOP853", rtol=1e-13, atol=1e-9,
                    t_eval=t)
    res = propagate(LEO, 0.0, DAY, force="j2")
    err = np.linalg.norm(res.state(t)[:, :3] - sol.y.T[:, :3], axis=1)
    assert err.max() < 1e-2                                      # measured: ~2e-5 m


def test_backward_integration_returns_to_start():
    fwd = propagate(ECC, 0.0, DAY)
    back = propagate(fwd.state(DAY), DAY, 0.0)
    assert back.outcome is Outcome.SUCCESS
    assert np.all(np.diff(back.step_times_s) < 0) and back.t_end_s == 0.0
    assert np.linalg.norm(back.state(0.0)[:3] - ECC[:3]) < 1e-5
    assert np.linalg.norm(back.state(0.0)[3:] - ECC[3:]) < 1e-8
    # dense output of the backward run at interior times agrees with the forward run
    t = np.linspace(DAY, 0.0, 97)
    assert np.abs(back.state(t)[:, :3] - fwd.state(t)[:, :3]).max() < 1e-5


def test_backward_two_body_against_kepler():
    res = propagate(LEO, 0.0, -20000.0, force="two-body")
    t = np.linspace(0.0, -20000.0, 201)
    assert np.abs(res.state(t)[:, :3] - kepler.propagate(LEO, t)[:, :3]).max() < 1e-6


def test_j2_conserves_energy_and_polar_angular_momentum():
    res = propagate(ECC, 0.0, DAY)
    st = res.state(np.linspace(0.0, DAY, 300))
    r = np.linalg.norm(st[:, :3], axis=1)
    z = st[:, 2]
    u_j2 = MU_EARTH * J2 * RE_EARTH ** 2 / (2 * r ** 3) * (3 * z ** 2 / r ** 2 - 1)
    energy = 0.5 * np.sum(st[:, 3:] ** 2, 1) - MU_EARTH / r + u_j2
    hz = st[:, 0] * st[:, 4] - st[:, 1] * st[:, 3]
    assert np.ptp(energy) < 1e-13 * abs(energy[0])
    assert np.ptp(hz) < 1e-13 * abs(hz[0])


# -- dense output -------------------------------------------------------------------------

def test_dense_output_derivatives_and_shapes():
    res = propagate(ECC, 0.0, 5000.0)
    t = np.linspace(0.0, 5000.0, 77)
    st = res.state(t)
    d1 = res.state(t, derivative=1)
    assert st.shape == (77, 6) and d1.shape == (77, 6)
    # the position series' derivative is the velocity series up to the recurrence's rounding (1 ulp)
    np.testing.assert_allclose(d1[:, :3], st[:, 3:], rtol=4e-15, atol=0)
    np.testing.assert_allclose(d1[:, 3:], taylor.acceleration(st[:, :3]), rtol=1e-12, atol=1e-15)
    # the jerk is the derivative of the acceleration along the motion
    d2 = res.state(t, derivative=2)
    h = 1e-3
    fd = (taylor.acceleration(res.state(t[1:-1] + h)[:, :3])
          - taylor.acceleration(res.state(t[1:-1] - h)[:, :3])) / (2 * h)
    np.testing.assert_allclose(d2[1:-1, 3:], fd, rtol=1e-6, atol=1e-12)
    assert res.state(123.0).shape == (6,)
    assert res.state(np.zeros((2, 3))).shape == (2, 3, 6)
    # the last step ends exactly at t_end and the state there is continuous
    assert res.step_times_s[-1] == 5000.0
    for tb in res.step_times_s[1:-1]:
        left = sp.evaluate(res.coefficients[np.searchsorted(res.step_times_s, tb) - 1, 0],
                           tb - res.step_times_s[np.searchsorted(res.step_times_s, tb) - 1])
        assert np.abs(left - res.state(tb)[:3]).max() < 1e-7


def test_dense_output_unsorted_times_and_bounds():
    res = propagate(ECC, 0.0, 20000.0)
    t = np.random.default_rng(0).uniform(0.0, 20000.0, 50)
    np.testing.assert_allclose(res.state(t), np.stack([res.state(ti) for ti in t]),
                               rtol=1e-15, atol=1e-9)
    with pytest.raises(ValueError):
        res.state(20001.0)
    with pytest.raises(ValueError):
        res.state(np.nan)


# -- outcomes and validation --------------------------------------------------------------

def test_outcome_step_limit():
    res = propagate(LEO, 0.0, DAY, max_steps=3)
    assert res.outcome is Outcome.STEP_LIMIT and res.n_steps == 3
    assert 0.0 < res.t_end_s < DAY
    res.state(res.t_end_s / 2)                                    # what was done is usable
    with pytest.raises(ProcessingError):
        res.raise_for_outcome()


def test_outcome_non_finite():
    res = propagate(np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0]), 0.0, 10.0)
    assert res.outcome is Outcome.NON_FINITE and res.n_steps == 0
    with pytest.raises(ProcessingError):
        res.raise_for_outcome()
    with pytest.raises(ValueError):
        res.state(0.0)


def test_zero_span_and_input_errors():
    res = propagate(LEO, 5.0, 5.0)
    assert res.outcome is Outcome.SUCCESS and res.n_steps == 0
    with pytest.raises(ValueError):
        propagate(LEO[:5], 0.0, 1.0)
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, 1.0, force="j4")
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, 1.0, tol=0.0)
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, np.inf)
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, 1.0, mu_sensitivity=True)
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, 1.0).stm(0.5)


@pytest.mark.parametrize("tol", [1e-6, 1e-9, 1e-12])
def test_looser_tolerances_meet_their_tolerance(tol):
    res = propagate(LEO, 0.0, 6000.0, force="two-body", tol=tol)
    t = np.linspace(0.0, 6000.0, 61)
    err = np.abs(res.state(t)[:, :3] - kepler.propagate(LEO, t)[:, :3]).max()
    assert err < 100 * tol * np.linalg.norm(LEO[:3])
    assert res.order == taylor.default_order(tol)


# -- batch mode ---------------------------------------------------------------------------

def test_batch_matches_kepler_and_single_runs():
    rng = np.random.default_rng(5)
    batch = LEO + rng.normal(size=(20, 6)) * np.array([2e4] * 3 + [20.0] * 3)
    batch[0] = ECC
    res = propagate(batch, 0.0, 3000.0, force="two-body")
    t = np.linspace(0.0, 3000.0, 31)
    st = res.state(t)
    assert st.shape == (20, 31, 6) and res.coefficients.shape[1:3] == (20, 3)
    assert np.abs(st - kepler.propagate(batch, t)).max(axis=(0, 1))[:3].max() < 1e-6
    single = propagate(batch[3], 0.0, 3000.0, force="two-body").state(t)
    assert np.abs(single - st[3])[:, :3].max() < 1e-6
    # a common step: the smallest any trajectory needs
    assert res.n_steps >= propagate(batch[3], 0.0, 3000.0, force="two-body").n_steps


def test_batch_j2_and_stm_match_single_runs():
    batch = np.stack([LEO, ECC, LEO * 1.01])
    t = np.linspace(0.0, 4000.0, 9)
    res = propagate(batch, 0.0, 4000.0, stm=True, mu_sensitivity=True)
    for i in range(3):
        one = propagate(batch[i], 0.0, 4000.0, stm=True, mu_sensitivity=True)
        assert np.abs(res.state(t)[i] - one.state(t))[:, :3].max() < 1e-6
        np.testing.assert_allclose(res.jacobian(t)[i], one.jacobian(t), rtol=1e-9,
                                   atol=1e-9 * np.abs(one.jacobian(t)).max())
    assert res.stm(t).shape == (3, 9, 6, 6) and res.dstate_dmu(t).shape == (3, 9, 6)


# -- sensitivities: seed 004 eqs. 19-21 (first order) -------------------------------------

def _fd_stm(state, t_end, t, force, steps=(10.0, 10.0, 10.0, 0.01, 0.01, 0.01)):
    cols = []
    for j, d in enumerate(steps):
        e = np.zeros(6)
        e[j] = d
        plus = propagate(state + e, 0.0, t_end, force=force).state(t)
        minus = propagate(state - e, 0.0, t_end, force=force).state(t)
        cols.append((plus - minus) / (2 * d))
    return np.stack(cols, axis=-1)


def _col_rel(a, b):
    return (np.linalg.norm(a - b, axis=-2) / np.linalg.norm(b, axis=-2)).max()


@pytest.mark.parametrize("force", ["two-body", "j2"])
@pytest.mark.parametrize("state,t_end", [(LEO, 600.0), (ECC, 30000.0)])
def test_stm_against_central_finite_differences(force, state, t_end):
    res = propagate(state, 0.0, t_end, force=force, stm=True)
    t = np.array([0.0, 0.31 * t_end, t_end])
    phi = res.stm(t)
    np.testing.assert_allclose(phi[0], np.eye(6), atol=0)
    assert _col_rel(phi[1:], _fd_stm(state, t_end, t[1:], force)) <= 1e-6   # measured ~1e-9
    # the state carried by the dual kernel is the same trajectory
    plain = propagate(state, 0.0, t_end, force=force)
    assert np.abs(res.state(t) - plain.state(t))[:, :3].max() < 1e-6


def test_two_body_stm_against_kepler_finite_differences():
    t = np.array([1000.0, 5000.0, 20000.0])
    phi = propagate(ECC, 0.0, 20000.0, force="two-body", stm=True).stm(t)
    cols = []
    for j, d in enumerate([10.0] * 3 + [0.01] * 3):
        e = np.zeros(6)
        e[j] = d
        cols.append((kepler.propagate(ECC + e, t) - kepler.propagate(ECC - e, t)) / (2 * d))
    assert _col_rel(phi, np.stack(cols, -1)) <= 1e-6


@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_stm_is_symplectic_det_one(force):
    res = propagate(ECC, 0.0, DAY, force=force, stm=True)
    phi = res.stm(np.linspace(0.0, DAY, 25))
    assert np.abs(np.linalg.det(phi) - 1.0).max() <= 1e-10
    # Phi^T J Phi = J (canonical r, v), relative to the size of the products
    jm = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.eye(3), np.zeros((3, 3))]])
    err = np.abs(np.swapaxes(phi, -1, -2) @ jm @ phi - jm).max(axis=(-1, -2))
    assert (err / np.abs(phi).max(axis=(-1, -2)) ** 2).max() < 1e-12


@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_dstate_dmu_against_finite_differences(force):
    t = np.array([300.0, 5000.0])
    res = propagate(ECC, 0.0, 5000.0, force=force, stm=True, mu_sensitivity=True)
    assert res.parameters == ("x", "y", "z", "vx", "vy", "vz", "mu")
    dmu = 1e-7 * MU_EARTH
    plus = propagate(ECC, 0.0, 5000.0, force=force, mu_m3_s2=MU_EARTH + dmu).state(t)
    minus = propagate(ECC, 0.0, 5000.0, force=force, mu_m3_s2=MU_EARTH - dmu).state(t)
    fd = (plus - minus) / (2 * dmu)
    got = res.dstate_dmu(t)
    assert (np.linalg.norm(got - fd, axis=-1) / np.linalg.norm(fd, axis=-1)).max() <= 1e-6
    # the state part of the jacobian is the plain STM
    np.testing.assert_array_equal(res.jacobian(t)[..., :6], res.stm(t))


@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_stm_composition(force):
    t1, t2 = 7000.0, 20000.0
    full = propagate(ECC, 0.0, t2, force=force, stm=True)
    second = propagate(full.state(t1), t1, t2, force=force, stm=True)
    comp = second.stm(t2) @ full.stm(t1)
    ref = full.stm(t2)
    assert _col_rel(comp, ref) < 1e-10


def test_stm_backward_is_inverse_of_forward():
    fwd = propagate(LEO, 0.0, 3000.0, stm=True)
    back = propagate(fwd.state(3000.0), 3000.0, 0.0, stm=True)
    prod = back.stm(0.0) @ fwd.stm(3000.0)
    assert np.abs(prod - np.eye(6)).max() < 1e-9


def test_powers_prefix_is_the_shorter_series_powers():
    """A shorter series' powers are the first rows of a longer one's, bit for bit (the dense
    output shares one set between the state and its derivative), and they are dt^k."""
    from trackproc.dynamics.taylor_dense import _powers

    dt = np.random.default_rng(3).uniform(-90.0, 90.0, 37)
    for n in range(1, 34):
        full = _powers(dt, n)
        np.testing.assert_allclose(full, dt[None, :] ** np.arange(n)[:, None], rtol=1e-13)
        for k in range(1, n + 1):
            assert np.array_equal(_powers(dt, k), full[:k])
