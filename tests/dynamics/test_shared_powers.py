"""The powers of the offsets kept from one trajectory to the next (``propagator._LAST_POWERS``).

A light-time solution on a new trajectory starts at the emission times where the previous model
evaluation ended; their powers are taken from the last trajectory instead of made again. The
reference is the same trajectory evaluated with nothing kept (a fresh propagation, the memo
cleared): every state, derivative and STM equal bit for bit; a trajectory evaluated at other
times makes its own; the kept arrays are read-only.
"""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import propagator

R0 = np.array([3774841.0, -1538034.0, 5924146.0])
V0 = np.array([-4816.6, 3936.4, 4091.1])
EPOCH = np.datetime64("2026-03-20T09:30:00", "ns")
SPAN = [-160.0, 160.0]


def _traj(dv=0.0):
    return propagator.propagate(R0, V0 + dv, EPOCH, SPAN, force="j2", stm=True)


def _read(traj, t):
    return traj.state(t), traj.state(t, derivative=1), traj.stm(t)


def test_kept_powers_give_the_fresh_numbers():
    t = np.linspace(-150.0, 150.0, 301) + 1e-3 * np.sin(np.arange(301.0))
    first = _traj()
    assert [run.n_steps for run in first.runs] == [1, 1]   # the shared expansion is what is tested
    _read(first, t)
    kept = propagator._LAST_POWERS[0]
    assert kept is not None and not kept[2].flags.writeable and not kept[1].flags.writeable

    second = _traj(dv=0.05)                     # another orbit, the same times: the powers reused
    reused = _read(second, t)
    assert propagator._LAST_POWERS[0] is kept

    propagator._LAST_POWERS[0] = None           # the reference: nothing kept, a fresh trajectory
    fresh = _read(_traj(dv=0.05), t)
    assert propagator._LAST_POWERS[0] is not kept
    for a, b in zip(reused, fresh):
        assert np.array_equal(a, b)


def test_other_times_make_their_own():
    t1 = np.linspace(-100.0, 100.0, 41)
    t2 = t1 + 0.5
    traj = _traj()
    traj.state(t1)
    kept = propagator._LAST_POWERS[0]
    s2 = traj.state(t2)
    assert propagator._LAST_POWERS[0] is not kept
    propagator._LAST_POWERS[0] = None
    assert np.array_equal(s2, _traj().state(t2))
