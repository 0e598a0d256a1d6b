"""A solution of the shared problem as a state file's :class:`~trackproc.io.statefile.State`
(:func:`solution_state`) and its RTN sigmas (:func:`sigma_rtn`): what ``estimate`` and ``filter``
write the same way."""

from __future__ import annotations

import math

import numpy as np

from trackproc.constants import force_model_constants
from trackproc.io.statefile import State


def sigma_rtn(rtn) -> dict:
    """The 1-sigmas of a 6 x 6 RTN covariance (m, m/s), named as the state file gives them."""
    rtn = np.asarray(rtn, float)
    return {"radial_m": math.sqrt(rtn[0, 0]), "along_m": math.sqrt(rtn[1, 1]), "cross_m": math.sqrt(rtn[2, 2]),
            "radial_m_s": math.sqrt(rtn[3, 3]), "along_m_s": math.sqrt(rtn[4, 4]), "cross_m_s": math.sqrt(rtn[5, 5])}


def solution_state(problem, epoch, x, names, sigma, covariance, force: str, eop, diagnostics: dict,
                   extra: dict) -> State:
    """The state file of a solution ``x`` (every estimated parameter, ``sigma``, ``covariance``) at
    ``epoch``: the force model it was fitted with (the problem's full model, else ``force``) and the
    Earth orientation's source."""
    x = np.asarray(x, float)
    full = problem.force_model is not None
    return State.from_vectors(epoch, x[:3], x[3:6], parameters=list(names), values=x, sigma=sigma,
                              covariance=covariance,
                              force_model=problem.force_model.label() if full else force,
                              constants=problem.force_model.describe() if full else force_model_constants(force),
                              eop_source=getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)",
                              diagnostics=diagnostics, extra=extra)
