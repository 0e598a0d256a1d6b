"""The propagation façade: GCRF in and out around the Taylor engine, against the simulator's
reference propagator (DOP853), round trips, the STM and covariance against finite differences,
time conversions and outcomes."""

from __future__ import annotations

import numpy as np
import pytest

from trackproc.dynamics import frames, propagator, reference, taylor
from trackproc.dynamics import timescales as ts
from trackproc.errors import ProcessingError

R0 = np.array([3774841.0, -1538034.0, 5924146.0])
V0 = np.array([-4816.6, 3936.4, 4091.1])
EPOCH = np.datetime64("2026-03-20T09:30:00", "ns")
JD = tuple(float(x) for x in ts.datetime64_to_jd_utc(EPOCH))
DAY = 86400.0


def test_against_simulator_reference_dop853_one_day_j2_within_1mm():
    t = np.linspace(-3600.0, DAY, 98)
    traj = propagator.propagate(R0, V0, EPOCH, t, force="j2")
    q = frames.QuasiInertialFrame.at(*JD).q              # what trackproc simulate integrates in
    r, v = reference.propagate_gcrf(R0, V0, t, q, "j2")
    s = traj.state(t)
    assert np.linalg.norm(s[:, :3] - r, axis=1).max() < 1e-3
    assert np.linalg.norm(s[:, 3:] - v, axis=1).max() < 1e-6
    assert traj.outcome is taylor.Outcome.SUCCESS and len(traj.runs) == 2


def test_two_body_against_reference():
    t = np.array([0.0, 600.0, 5400.0])
    traj = propagator.propagate(R0, V0, EPOCH, t, force="two-body")
    q = frames.QuasiInertialFrame.at(*JD).q
    r, _ = reference.propagate_gcrf(R0, V0, t, q, "two-body")
    assert np.abs(traj.state(t)[:, :3] - r).max() < 1e-5
    assert traj.j2 == 0.0 and traj.force == "two-body"


def test_round_trip_forward_a_day_then_back():
    later = EPOCH + np.timedelta64(86400, "s")
    fwd = propagator.propagate(R0, V0, EPOCH, DAY, stm=True)
    end = fwd.state(DAY)
    back = propagator.propagate(end[:3], end[3:], later, -DAY, stm=True, frame=fwd.frame)
    start = back.state(-DAY)
    assert np.abs(start[:3] - R0).max() < 1e-4          # metres, after two days of integration
    assert np.abs(start[3:] - V0).max() < 1e-7
    # Φ(back) Φ(fwd) = I to round-off: judged against the size of the products' terms (the
    # position-from-velocity block reaches 1e5 s, so an absolute 1e-6 sat at the round-off floor)
    phi_b, phi_f = back.stm(-DAY), fwd.stm(DAY)
    assert (np.abs(phi_b @ phi_f - np.eye(6)) / (np.abs(phi_b) @ np.abs(phi_f))).max() < 1e-11
    # the J2 axis is that of the reference epoch: re-referencing a day later moves the
    # round trip by decimetres (precession-nutation, 0.15 arcsec a day)
    other = propagator.propagate(end[:3], end[3:], later, -DAY).state(-DAY)
    assert 0.05 < np.abs(other[:3] - R0).max() < 2.0


def test_epoch_state_identity_stm_and_both_directions():
    traj = propagator.propagate(R0, V0, EPOCH, [-300.0, 0.0, 300.0], stm=True)
    assert np.array_equal(traj.state(0.0), np.r_[R0, V0])
    assert np.allclose(traj.stm(0.0), np.eye(6), atol=1e-15)
    s = traj.state(np.array([-300.0, 300.0]))
    assert np.all(np.linalg.norm(s[:, :3], axis=1) > 7.0e6)
    only_back = propagator.propagate(R0, V0, EPOCH, [-60.0, 0.0])
    assert len(only_back.runs) == 1 and np.array_equal(only_back.state(0.0), np.r_[R0, V0])
    only_epoch = propagator.propagate(R0, V0, EPOCH, 0.0)
    assert np.array_equal(only_epoch.state(np.array([0.0])), np.r_[R0, V0][None])
    with pytest.raises(ValueError, match="outside the propagated interval"):
        only_back.state(10.0)
    with pytest.raises(ValueError, match="no STM"):
        only_back.stm(-10.0)


def test_quasi_inertial_frame_output_and_derivative():
    traj = propagator.propagate(R0, V0, EPOCH, 600.0)
    qi = traj.state(100.0, frame="quasi-inertial")
    g = traj.state(100.0)
    q = traj.frame.q
    assert np.allclose(qi[:3], q @ g[:3], rtol=0, atol=1e-8)
    acc = traj.state(100.0, derivative=1)[3:]
    assert np.allclose(acc, reference.acceleration_gcrf(g[:3], g[3:], q, "j2")[0], rtol=1e-10)
    with pytest.raises(ValueError, match="unknown frame"):
        traj.state(1.0, frame="itrf")


@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_gcrf_stm_against_central_finite_differences(force):
    t = np.array([-1800.0, 600.0, 5400.0])
    traj = propagator.propagate(R0, V0, EPOCH, t, force=force, stm=True)
    phi = traj.stm(t)
    x0 = np.r_[R0, V0]
    h = np.array([1.0] * 3 + [1e-3] * 3)
    fd = np.zeros_like(phi)
    for k in range(6):
        e = np.zeros(6)
        e[k] = h[k]
        plus = propagator.propagate((x0 + e)[:3], (x0 + e)[3:], EPOCH, t, force=force, frame=traj.frame)
        minus = propagator.propagate((x0 - e)[:3], (x0 - e)[3:], EPOCH, t, force=force, frame=traj.frame)
        fd[:, :, k] = (plus.state(t) - minus.state(t)) / (2 * h[k])
    rel = np.linalg.norm(phi - fd, axis=1) / np.linalg.norm(fd, axis=1)
    assert rel.max() < 1e-6
    assert np.abs(np.linalg.det(phi) - 1.0).max() < 1e-10


def test_covariance_is_phi_p_phi_transpose():
    t = np.array([0.0, 3600.0])
    traj = propagator.propagate(R0, V0, EPOCH, t, stm=True)
    p0 = np.diag([100.0, 100.0, 100.0, 1e-2, 1e-2, 1e-2])
    p0[0, 3] = p0[3, 0] = 0.5
    cov = traj.covariance(t, p0)
    assert np.allclose(cov[0], p0, rtol=1e-12, atol=1e-12)
    phi = traj.stm(3600.0)
    assert np.allclose(cov[1], phi @ p0 @ phi.T, rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(cov[1]) > 0)
    with pytest.raises(ValueError, match="6 x 6"):
        traj.covariance(t, np.eye(7))


def test_time_conversions_count_leap_seconds():
    epoch = np.datetime64("2016-12-31T23:59:00", "ns")
    traj = propagator.propagate(R0, V0, epoch, 600.0)
    later = np.array(["2017-01-01T00:01:00"], dtype="datetime64[ns]")
    assert traj.seconds(later)[0] == pytest.approx(121.0, abs=1e-6)      # 2016-12-31 had 86401 s
    assert traj.times_utc(121.0) == later[0]
    assert traj.seconds(epoch) == pytest.approx(0.0, abs=1e-9)
    # UTC labels wherever times are taken
    by_label = propagator.propagate(R0, V0, epoch, later)
    assert by_label.t_max_s == pytest.approx(121.0, abs=1e-6)
    assert np.array_equal(by_label.state(later), by_label.state(by_label.seconds(later)))


def test_step_limit_outcome_raises_processing_error():
    traj = propagator.propagate(R0, V0, EPOCH, 2 * DAY, max_steps=2)
    assert traj.outcome is taylor.Outcome.STEP_LIMIT
    with pytest.raises(ProcessingError, match="step_limit"):
        traj.raise_for_outcome()


def test_steps_are_in_time_order_and_evaluate_to_the_states():
    traj = propagator.propagate(R0, V0, EPOCH, [-3000.0, 3000.0], stm=True)
    steps = traj.steps()
    assert np.all(np.diff(steps.t_lo_s) > 0) and np.all(steps.t_hi_s > steps.t_lo_s)
    assert steps.t_lo_s[0] == -3000.0 and steps.t_hi_s[-1] == 3000.0
    assert steps.sensitivities.shape[:3] == (steps.t_lo_s.size, 3, 6)
    t = np.array([-2999.0, -1.0, 1.0, 2999.0])
    k = steps.locate(t)
    from trackproc.dynamics import spectra as sp
    pos = np.stack([sp.evaluate(steps.coefficients[i], ti - steps.t_expand_s[i]) for i, ti in zip(k, t)])
    assert np.abs(pos - traj.state(t, frame="quasi-inertial")[:, :3]).max() < 1e-6


def test_input_errors():
    with pytest.raises(ValueError, match="finite"):
        propagator.propagate([np.nan, 0, 0], V0, EPOCH, 10.0)
    with pytest.raises(ValueError, match="at least one"):
        propagator.propagate(R0, V0, EPOCH, [])
    with pytest.raises(ValueError, match="force model"):
        propagator.propagate(R0, V0, EPOCH, 10.0, force="j3")


def _fresh(t_span=(-900.0, 900.0)):
    return propagator.propagate(R0, V0, EPOCH, list(t_span), force="j2", stm=True)


def test_kept_times_give_the_numbers_of_a_fresh_trajectory_in_any_order():
    """The state, its derivative and the STM at the same times share one run split, location and
    set of powers (kept for the last times): bit for bit what a trajectory that never saw those
    times gives, whatever the order of the calls; and the GCRF state is the quasi-inertial one
    times q, r and v alike (the product the rotation makes)."""
    t = np.linspace(-800.0, 800.0, 161)
    a = _fresh()
    first = a.state(t), a.state(t, derivative=1), a.stm(t), a.state(t, derivative=2)
    for order in ((3, 2, 1, 0), (1, 0, 3, 2)):
        b = _fresh()
        got = {}
        for i in order:
            got[i] = b.stm(t) if i == 2 else b.state(t, derivative=(0, 1, None, 2)[i])
        for i in range(4):
            assert np.array_equal(got[i], first[i])
    qi = _fresh().state(t, frame="quasi-inertial")
    q = a.frame.q
    rotated = np.concatenate([qi[:, :3] @ q, qi[:, 3:] @ q], axis=-1)
    off = t != 0.0                                                  # the epoch row is the state as given
    assert np.array_equal(first[0][off], rotated[off])
    assert np.array_equal(first[0][~off][0], np.concatenate([R0, V0]))
    big = a.rotation
    assert np.array_equal(first[2], big.T @ _fresh().stm(t, frame="quasi-inertial") @ big)


def test_times_out_of_order_and_changed_by_the_caller():
    """Unsorted times (selections rather than slices) give the sorted times' numbers, permuted;
    an array the caller changes in place after a call is read afresh, and its old values again
    give the old numbers (what is kept is a copy)."""
    t = np.linspace(-800.0, 800.0, 161)
    ref = _fresh().state(t)
    perm = np.random.default_rng(5).permutation(t.size)
    traj = _fresh()
    assert np.array_equal(traj.state(t[perm]), ref[perm])
    arr = t.copy()
    assert np.array_equal(traj.state(arr), ref)
    arr += 50.0
    assert np.array_equal(traj.state(arr), _fresh().state(t + 50.0))
    arr -= 50.0
    assert np.array_equal(traj.state(t), ref)
    assert np.array_equal(traj.state(arr), _fresh().state(arr))
    epoch = traj.state(np.array([0.0, 10.0]))
    assert np.array_equal(epoch[0], np.concatenate([R0, V0]))       # the epoch state, unrotated


def test_times_outside_a_one_sided_trajectory_are_refused():
    traj = propagator.propagate(R0, V0, EPOCH, [0.0, 600.0], force="j2")
    with pytest.raises(ValueError, match="outside the propagated interval"):
        traj.state(np.array([-10.0, 10.0]))
    assert traj.state(np.array([10.0, 20.0])).shape == (2, 6)
