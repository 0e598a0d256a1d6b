"""The replace-or-keep rule of :mod:`trackproc.methods.estimation.decision` on a solved problem: the
solution's move of the predicted position ``horizon`` after the solution epoch, and its covariance
there, through the state transition matrix of the problem's own force model."""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import propagator
from trackproc.errors import ProcessingError
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr


#: Times at which the predictions are compared over the horizon: the epoch, then evenly spaced.
HORIZON_SAMPLES = 96
#: Integration tolerance of the horizon's STM (Taylor models; the full model's DOP853 keeps its own
#: rtol, 1e-12). The decision reads the maps to a few digits (a probability against 0.9, metres
#: against their sigma): at 1e-12 the maps are within ~4e-10 of the 1e-15 default's over a day,
#: the probabilities within 1e-12, and the day's STM costs ~30 % less CPU.
HORIZON_TOL = 1e-12


def horizon_maps(x, epoch, horizon_days: float, force: str, frame=None, eop=None, force_model=None):
    """``(times (days), ∂ position(t) / ∂ state(epoch) (K, 3, 6))``, GCRF, along the orbit ``x`` at
    the epoch and :data:`HORIZON_SAMPLES` times over the ``horizon_days`` after it; None if the orbit
    cannot be propagated that far (it decays, or the integration fails)."""
    x = np.asarray(x, float)
    t = float(horizon_days) * 86400.0 * np.arange(0, HORIZON_SAMPLES + 1) / HORIZON_SAMPLES
    try:
        traj = propagator.propagate(x[:3], x[3:6], epoch, t,
                                    force=force_model if force == "full" else force, frame=frame, eop=eop, stm=True,
                                    tol=HORIZON_TOL)
        traj.raise_for_outcome()
        phi = np.asarray(traj.stm(t), float)
    except (ArithmeticError, ValueError, ProcessingError):
        return None
    return (t / 86400.0, phi[:, :3, :6]) if np.all(np.isfinite(phi)) else None


def by_prediction(problem, x, cov, priors, horizon_days: float = dm.HORIZON_DAYS, source=None):
    """:func:`trackproc.methods.estimation.decision.by_prediction` of the solution ``x`` (covariance
    ``cov``, state first) of ``problem`` (its epoch, force model and frame) against the centre of its
    state a-priori ``priors``, over the ``horizon_days`` after the epoch. None without a full state
    a-priori, or when the orbit cannot be propagated to the horizon (the solution then stands)."""
    centre = pr.state_prior_centre(priors)
    if not np.all(np.isfinite(centre)):
        return None
    maps = horizon_maps(x[:6], problem.epoch, horizon_days, problem.force, problem.frame, problem.eop,
                        problem.force_model)
    if maps is None:
        return None
    return dm.by_prediction(maps[1], maps[0], np.asarray(x, float)[:6] - centre, np.asarray(cov, float)[:6, :6],
                            horizon_days, source)
