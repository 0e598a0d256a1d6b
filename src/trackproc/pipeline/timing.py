"""Does a solution's timing contradict its TLE? (:func:`tle_timing`; docs/refine.md, "Timing").

One Doppler pass sees the along-track position of the orbit through the time of closest
approach, so a station whose time tags are off by ``τ`` moves the solution along its track by
``v τ`` (0.5 s is 3.7 km in LEO), with a posterior sigma that knows nothing of it; a station's
clock offset does the same to an estimate from its passes. On DopTrack the passes need shifts of
0.5-1 s against their TLEs, nearly uncorrelated between passes 95 minutes apart: errors of each
pass, not of the orbit (docs/refine.md, "The whole difference is timing"). The data cannot tell
the two apart. When the initial state is a TLE, whose accuracy is known (TLE differencing,
:data:`trackproc.methods.tle_fit.TLE_APRIORI`), the solution's along-track move from it is tested
against that accuracy; beyond it (99.9 %) the covariance takes the shift as a possible time-tag
error — ``g gᵀ τ²``, with ``g`` how the state the samples describe moves per second of their time
tags (:func:`time_tag_rate`: the orbit shifted along its track and turned with the Earth) — so
that it covers the error whichever of the two is right, and the verdict says so (reason
``timing``, ``suspect``). ``refine --time-tag-sigma`` adds the same kind of term for a time-tag
error the user states. Used by ``refine`` and ``estimate``.
"""

from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np

from trackproc.constants import OMEGA_EARTH
from trackproc.dynamics import propagator
from trackproc.dynamics.rtn import rtn_jacobian
from trackproc.errors import InputError, ProcessingError
from trackproc.io.tle import is_tle_state, parse_tle, tle_epoch, tle_state
from trackproc.methods.estimation.prior import TLE_APRIORI, TLE_APRIORI_MAX_AGE_DAYS
from trackproc.methods.quality import chi2_limit


def time_tag_rate(x, epoch, force: str, frame=None, eop=None) -> Optional[np.ndarray]:
    """How the state at ``epoch`` that a pass's samples describe moves per second of a time-tag
    offset (6,): samples tagged ``Δt`` late are those of the orbit shifted by ``−Δt`` and turned
    by ``ω⊕ Δt`` about the Earth's axis (the station is where it is ``Δt`` later; the gravity
    field of the force model is axisymmetric), so ``d/dΔt = (−v + ω⊕ ẑ × r, −a + ω⊕ ẑ × v)`` with
    ``a`` the force model's acceleration. ``ẑ`` is the GCRF pole: the Earth's axis is 6e-3 rad
    from it in 2026, a 0.04 % change of this vector. None if the orbit cannot be propagated."""
    x = np.asarray(x, float)
    try:
        traj = propagator.propagate(x[:3], x[3:6], epoch, [-1.0, 1.0], force=force, frame=frame,
                                    eop=eop).raise_for_outcome()
        rate = np.asarray(traj.state(np.array([0.0]), derivative=1), float).reshape(6)
    except (ArithmeticError, ValueError, ProcessingError):
        return None
    spin = np.array([0.0, 0.0, OMEGA_EARTH])
    return np.r_[-rate[:3] + np.cross(spin, x[:3]), -rate[3:] + np.cross(spin, x[3:6])]


def initial_tle(initial):
    """The TLE whose SGP4 state ``initial`` is (:func:`~trackproc.io.tle.tle_state` records its
    lines), or None."""
    if not is_tle_state(initial):
        return None
    try:            # the lines were parsed once already (tle_state); a hand-made state may hold others
        return parse_tle("\n".join(initial.extra["tle"]))
    except (InputError, KeyError, TypeError, ValueError):
        return None


def tle_age_days(initial, epoch) -> Optional[float]:
    """Days between the initial TLE's epoch and ``epoch`` (None unless ``initial`` is a TLE's state)."""
    tle = initial_tle(initial)
    if tle is None:
        return None
    return abs(float((np.datetime64(epoch, "ns") - tle_epoch(tle)) / np.timedelta64(1, "s"))) / 86400.0


def tle_reference(initial, epoch, eop=None) -> Optional[np.ndarray]:
    """The initial TLE's SGP4 state at ``epoch`` (6,), the reference of its accuracy (None unless a TLE)."""
    tle = initial_tle(initial)
    if tle is None:
        return None
    st = tle_state(tle, at=np.datetime64(epoch, "ns"), eop=eop)
    return np.r_[st.r_m, st.v_m_s]


def tle_timing(initial, epoch, x0, x, cov, rate: Callable[[], Optional[np.ndarray]], mu: float) -> Optional[dict]:
    """The along-track move of the solution ``x`` (covariance ``cov``, state first) from the
    initial TLE's state ``x0`` at ``epoch``, against the TLE's accuracy at its age: ``{along_m,
    shift_s, tle_sigma_m, posterior_sigma_m, z, limit, age_days, inflated, covariance}``
    (``covariance``: ``cov`` with the time-shift term when the test fires, else ``cov``; ``rate``
    gives :func:`time_tag_rate` at ``x``, two-body ``ẋ`` when it cannot). None unless the
    initial state is a TLE within the ages its accuracy was measured at."""
    age = tle_age_days(initial, epoch)
    if age is None or age > TLE_APRIORI_MAX_AGE_DAYS:
        return None
    x = np.asarray(x, float)
    cov = np.asarray(cov, float)
    r, v = x[:3], x[3:6]
    speed = float(np.linalg.norm(v))
    along_row = rtn_jacobian(r, v, rotating=False)[1]          # along-track position (m) per state
    along = float(along_row @ (x[:6] - np.asarray(x0, float)[:6]))
    posterior = math.sqrt(max(float(along_row @ cov[:6, :6] @ along_row), 0.0))
    tle_sigma = TLE_APRIORI["along_m"] + TLE_APRIORI["along_m_per_day"] * age
    z = along / math.hypot(tle_sigma, posterior)
    limit = math.sqrt(chi2_limit(1))
    out = {"along_m": along, "shift_s": -along / speed, "tle_sigma_m": tle_sigma, "posterior_sigma_m": posterior,
           "z": z, "limit": limit, "age_days": age, "inflated": abs(z) > limit, "covariance": cov}
    if out["inflated"]:
        # the move the timing explains: g dt, g the state's move per second of time tag, dt to the
        # along-track move
        g = rate()
        if g is None:
            g = np.r_[v, -mu * r / float(np.linalg.norm(r)) ** 3]
        dt = along / float(along_row @ g[:6])
        cov = cov.copy()
        cov[:6, :6] += dt ** 2 * np.outer(g, g)
        out["covariance"] = cov
    return out


def add_timing_reason(q, timing: Optional[dict], moved_by: str = "the pass") -> None:
    """Reason ``timing`` of :func:`tle_timing`'s test (nothing when it was not made)."""
    if timing is None:
        return
    t = timing
    head = (f"{moved_by} moves the TLE's state {t['along_m'] / 1000:+.3g} km along-track ({t['shift_s']:+.3g} s), "
            f"{abs(t['z']):.3g} sigma of a {t['age_days']:.2g}-day-old TLE's accuracy ({t['tle_sigma_m']:.0f} m, "
            f"TLE differencing) with the solution's sigma")
    if t["inflated"]:
        q.add("timing", "suspect", head + ": a time-tag error of the data and an error of the TLE look the same; "
              "the covariance includes the shift as a possible time-tag error", value=abs(t["z"]), limit=t["limit"])
    else:
        q.add("timing", "ok", head, value=abs(t["z"]), limit=t["limit"])


def timing_warning(timing: dict, moved_by: str = "the pass") -> str:
    """The summary's warning of a :func:`tle_timing` test that fired."""
    return (f"{moved_by} moves the TLE's state {timing['along_m'] / 1000:+.3g} km along-track "
            f"({timing['shift_s']:+.3g} s), {abs(timing['z']):.3g} sigma of the TLE's accuracy: a time-tag error "
            "looks the same; the covariance includes it (see docs/refine.md, Timing)")
