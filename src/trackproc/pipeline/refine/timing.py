"""Does a pass's timing contradict its TLE? (:func:`tle_timing`; docs/refine.md, "Timing").

One Doppler pass sees the along-track position of the orbit through the time of closest
approach, so a station whose time tags are off by ``τ`` moves the refined state along its track
by ``v τ`` (0.5 s is 3.7 km in LEO), with a posterior sigma that knows nothing of it. On DopTrack
the passes need shifts of 0.5-1 s against their TLEs, nearly uncorrelated between passes 95
minutes apart: errors of each pass, not of the orbit (docs/refine.md, "The whole difference is
timing"). One pass cannot tell the two apart. When the stale state is a TLE, whose accuracy is
known (TLE differencing, :data:`trackproc.methods.tle_fit.TLE_APRIORI`), the refined state's
along-track move is tested against it; when the move is beyond the TLE's accuracy (99.9 %), the
covariance takes the shift as a possible time-tag error of the pass — ``g gᵀ τ²``, with ``g``
how the state a pass describes moves per second of its time tags (the orbit shifted along its
track and turned with the Earth, :func:`~trackproc.pipeline.refine.traverse.time_tag_direction`)
— so that it covers the error whichever of the two is right, and the verdict says so (reason
``timing``, ``suspect``). ``--time-tag-sigma`` is the same term for a time-tag error the user
states.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from trackproc.dynamics.rtn import rtn_jacobian
from trackproc.errors import InputError
from trackproc.methods.quality import chi2_limit
from trackproc.io.tle import is_tle_state
from trackproc.pipeline.refine.problem import Refinement
from trackproc.pipeline.refine.traverse import time_tag_direction


def tle_age_days(ref: Refinement) -> Optional[float]:
    """Days between the stale TLE's epoch and the solution epoch (None unless the stale state is a TLE)."""
    if not is_tle_state(ref.initial):
        return None
    from trackproc.io.tle import parse_tle, tle_epoch

    try:            # the lines were parsed once already (tle_state); a hand-made state may hold others
        epoch = tle_epoch(parse_tle("\n".join(ref.initial.extra["tle"])))
    except (InputError, KeyError, TypeError, ValueError):
        return None
    return abs(float((ref.problem.epoch - epoch) / np.timedelta64(1, "s"))) / 86400.0


def tle_timing(ref: Refinement, x, cov) -> Optional[dict]:
    """The along-track move of the refined state ``x`` (covariance ``cov``) from its stale TLE,
    against the TLE's accuracy at its age: ``{along_m, shift_s, tle_sigma_m, posterior_sigma_m, z,
    limit, age_days, inflated, covariance}`` (``covariance``: ``cov`` with the time-shift term when
    the test fires, else ``cov``). None unless the stale state is a TLE within the ages its accuracy
    was measured at."""
    from trackproc.methods.tle_fit import TLE_APRIORI, TLE_APRIORI_MAX_AGE_DAYS

    age = tle_age_days(ref)
    if age is None or age > TLE_APRIORI_MAX_AGE_DAYS:
        return None
    x = np.asarray(x, float)
    cov = np.asarray(cov, float)
    r, v = x[:3], x[3:6]
    speed = float(np.linalg.norm(v))
    along_row = rtn_jacobian(r, v, rotating=False)[1]          # along-track position (m) per state
    along = float(along_row @ (x[:6] - np.asarray(ref.x0[:6], float)))
    posterior = math.sqrt(max(float(along_row @ cov[:6, :6] @ along_row), 0.0))
    tle_sigma = TLE_APRIORI["along_m"] + TLE_APRIORI["along_m_per_day"] * age
    z = along / math.hypot(tle_sigma, posterior)
    limit = math.sqrt(chi2_limit(1))
    out = {"along_m": along, "shift_s": -along / speed, "tle_sigma_m": tle_sigma, "posterior_sigma_m": posterior,
           "z": z, "limit": limit, "age_days": age, "inflated": abs(z) > limit, "covariance": cov}
    if out["inflated"]:
        # the move the pass's timing explains: g dt with g the state's move per second of time tag
        # (two-body d(x)/dt if the orbit cannot be propagated), dt to the along-track move
        g = time_tag_direction(ref, x)
        if g is None:
            g = np.r_[v, -ref.mu * r / float(np.linalg.norm(r)) ** 3]
        dt = along / float(along_row @ g[:6])
        cov = cov.copy()
        cov[:6, :6] += dt ** 2 * np.outer(g, g)
        out["covariance"] = cov
    return out


def add_timing_reason(q, timing: Optional[dict]) -> None:
    """Reason ``timing`` of :func:`tle_timing`'s test (nothing when it was not made)."""
    if timing is None:
        return
    t = timing
    head = (f"the pass moves the TLE's state {t['along_m'] / 1000:+.3g} km along-track ({t['shift_s']:+.3g} s), "
            f"{abs(t['z']):.3g} sigma of a {t['age_days']:.2g}-day-old TLE's accuracy ({t['tle_sigma_m']:.0f} m, "
            f"TLE differencing) with the refined sigma")
    if t["inflated"]:
        q.add("timing", "suspect", head + ": a time-tag error of the pass and an error of the TLE look the same in "
              "one pass; the covariance includes the shift as a possible time-tag error", value=abs(t["z"]),
              limit=t["limit"])
    else:
        q.add("timing", "ok", head, value=abs(t["z"]), limit=t["limit"])
