"""The replace-or-keep decision on a solved problem (pipeline/od/decision.py): the horizon's maps
at their integration tolerance against the propagator's default (1e-15) and, for two-body, against
the closed-form Kepler STM's finite differences."""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import propagator
from trackproc.methods.estimation import decision as dm
from trackproc.pipeline.od import decision as od

R0 = np.array([6878137.0, 0.0, 0.0])
V0 = np.array([0.0, 5000.0, 5500.0])
EPOCH = np.datetime64("2026-03-20T09:30:00")


def test_the_horizon_maps_and_the_decision_hold_at_the_default_tolerance():
    """J2 over a day: the maps at HORIZON_TOL within 1e-8 of the default tolerance's (scaled by
    their largest entry), and the decision's probability, move and sigma within 1e-9 of it."""
    x = np.r_[R0, V0]
    times, maps = od.horizon_maps(x, EPOCH, 1.0, "j2")
    t = times * 86400.0
    ref = propagator.propagate(R0, V0, EPOCH, t, force="j2", stm=True).stm(t)[:, :3, :6]
    assert maps.shape == (od.HORIZON_SAMPLES + 1, 3, 6) and times[-1] == 1.0
    assert np.max(np.abs(maps - ref)) < 1e-8 * np.max(np.abs(ref))
    rng = np.random.default_rng(3)
    a = rng.normal(size=(6, 6)) * np.r_[30.0, 30.0, 30.0, 0.03, 0.03, 0.03][:, None]
    cov = a @ a.T
    change = np.r_[40.0, -25.0, 10.0, 0.02, 0.01, -0.03]
    mine = dm.by_prediction(maps, times, change, cov, 1.0)
    full = dm.by_prediction(ref, times, change, cov, 1.0)
    assert mine.action == full.action
    assert abs(mine.probability - full.probability) < 1e-9
    assert abs(mine.moved_m / full.moved_m - 1) < 1e-9 and abs(mine.moved_sigma_m / full.moved_sigma_m - 1) < 1e-9


def test_the_two_body_horizon_maps_are_the_finite_differences_of_the_orbit():
    """Two-body: each column of the maps against central differences of the propagated position
    (1 m and 1 mm/s perturbations of the epoch state), to their truncation error."""
    x = np.r_[R0, V0]
    times, maps = od.horizon_maps(x, EPOCH, 0.25, "two-body")
    t = times * 86400.0
    steps = np.r_[1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3]
    for j in range(6):
        dx = np.zeros(6)
        dx[j] = steps[j]
        plus = propagator.propagate((x + dx)[:3], (x + dx)[3:], EPOCH, t, force="two-body").state(t)[:, :3]
        minus = propagator.propagate((x - dx)[:3], (x - dx)[3:], EPOCH, t, force="two-body").state(t)[:, :3]
        fd = (plus - minus) / (2 * steps[j])
        assert np.max(np.abs(maps[:, :, j] - fd)) < 1e-5 * np.max(np.abs(fd)), j
