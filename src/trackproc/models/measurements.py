"""The simulator's measurement model: every observable of every station at the reception times.

Pure functions on numpy arrays, SI units, all vectors in GCRF (m, m/s, s). Every sample is
time-tagged at **reception** on the ground, ``t_r`` (as Orekit's ground measurements are).
The physics has one home: the light-time solver is :mod:`trackproc.models.light_time`, the
observables (range, both range-rate models, Doppler, az/el, one- and two-way) are
:mod:`trackproc.models.observables`, shared with the estimator
(:mod:`trackproc.models.observation`). What is the simulator's own is how it gets the satellite
at the emission time: a Taylor expansion about ``t_r`` with the force model's acceleration and
jerk, ``r(t_r - τ) = r - v τ + a τ²/2 - j τ³/6`` (truncation below 1e-14 m for LEO and GEO:
the next term is ``snap τ⁴/24``), from samples of the reference (DOP853) orbit at ``t_r``. The
light-time iteration then starts at τ = 0 (two Newton iterations in practice).

The independent implementation this module replaced is kept as a test oracle,
``tests/oracles/measurements_oracle.py``; the tests compare both the simulator and the
estimator against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics.geodesy import StationTrack, station_gcrf  # noqa: F401  (re-exported)
from trackproc.models import light_time as lt
from trackproc.models.light_time import LIGHT_TIME_TOL_S  # noqa: F401  (re-exported)
from trackproc.models.observables import (azel, check_mode, doppler_hz, range_rate_from_doppler,  # noqa: F401
                                          range_rate_partials, range_rate_value, up_rate_partials, wrap_2pi)
from trackproc.vocabulary import LINK_MODES as MODES  # noqa: F401
from trackproc.vocabulary import RANGE_RATE_MODELS  # noqa: F401


# --------------------------------------------------------------------------- light time

def _taylor_back(r, v, a, j, tau):
    """Satellite state (..., 6) ``τ`` seconds before the expansion point (Taylor to the jerk term)."""
    t = np.asarray(tau, float)[..., None]
    return np.concatenate([r - v * t + a * (t * t / 2) - j * (t * t * t / 6), v - a * t + j * (t * t / 2)], -1)


def light_time_down(r_sat, v_sat, a_sat, j_sat, r_st, *, c: float = C_LIGHT, tol_s: float = LIGHT_TIME_TOL_S,
                    max_iter: int = 10) -> lt.DownLeg:
    """Down leg of signals received at ``r_st`` at ``t_r`` (:func:`trackproc.models.light_time.solve_down_leg`).

    ``r_sat, v_sat, a_sat, j_sat``: satellite position, velocity, acceleration, jerk at ``t_r``
    (GCRF; shape (..., 3)); ``r_st``: station at ``t_r``. Raises ``ArithmeticError`` if the
    iteration does not converge.
    """
    r_sat, v_sat, a_sat, j_sat, r_st = (np.asarray(x, float) for x in (r_sat, v_sat, a_sat, j_sat, r_st))
    tau0 = np.zeros(np.broadcast_shapes(r_sat.shape, r_st.shape)[:-1])
    return lt.solve_down_leg(lambda tau: _taylor_back(r_sat, v_sat, a_sat, j_sat, tau), r_st, tau0, c=c,
                             tol_s=tol_s, max_iter=max_iter)


# --------------------------------------------------------------------------- observables

#: a pass file's measurement kind -> the :class:`Observables` field that predicts it
KIND_FIELDS = {"range": "range_m", "range_rate": "range_rate_m_s", "doppler": "doppler_hz",
               "elevation": "elevation_rad", "azimuth": "azimuth_rad"}


@dataclass(frozen=True)
class Observables:
    """Modelled values at the reception times (arrays of one shape, SI units).

    ``range_m`` (one-way: ρ; two-way: round trip / 2), ``range_rate_m_s`` (by the chosen
    model; two-way: mean of both legs), ``doppler_hz`` (carrier-scaled, no offset),
    ``elevation_rad``, ``azimuth_rad``, ``light_time_s`` (one-way: down leg; two-way: round trip).
    """

    range_m: np.ndarray
    range_rate_m_s: np.ndarray
    doppler_hz: np.ndarray
    elevation_rad: np.ndarray
    azimuth_rad: np.ndarray
    light_time_s: np.ndarray

    def by_kind(self) -> dict:
        """The values that predict each measurement kind of a pass file (:data:`KIND_FIELDS`)."""
        return {kind: getattr(self, name) for kind, name in KIND_FIELDS.items()}


def observables(r_sat, v_sat, a_sat, j_sat, r_st, v_st, a_st, gcrf_to_itrf_matrix, lat_rad, lon_rad, *,
                carrier_hz: float, mode: str = "one-way", range_rate_model: str = "doppler",
                c: float = C_LIGHT) -> Observables:
    """All observables of one station at the reception times (eqs. 1-7 of
    :mod:`trackproc.models.observables`, light time by :mod:`trackproc.models.light_time`).

    Satellite state (position, velocity, acceleration, jerk) and station state (position,
    velocity, acceleration) are GCRF at ``t_r`` with matching shapes (..., 3);
    ``gcrf_to_itrf_matrix`` (..., 3, 3) at ``t_r``.
    """
    check_mode(mode)
    down = light_time_down(r_sat, v_sat, a_sat, j_sat, r_st, c=c)
    r_e, v_e = down.state[..., :3], down.state[..., 3:]
    rr = range_rate_value(r_e, v_e, r_st, v_st, range_rate_model, c)
    rng, lt_s = down.rho_m, down.tau_s
    if mode == "two-way":
        r_st_b, v_st_b, a_st_b = np.broadcast_arrays(*(np.asarray(x, float) for x in (r_st, v_st, a_st)))
        up = lt.solve_up_leg(r_e, r_st_b, v_st_b, a_st_b, down.tau_s, c=c)
        rr_up = up_rate_partials(r_e, v_e, up.r_st, up.v_st, a_st_b, rr, range_rate_model, c)[0]
        rng = 0.5 * (down.rho_m + up.rho_m)
        rr = 0.5 * (rr + rr_up)
        lt_s = down.tau_s + up.tau_s
    az, el = azel(r_e - np.asarray(r_st, float), gcrf_to_itrf_matrix, lat_rad, lon_rad)
    return Observables(range_m=rng, range_rate_m_s=rr, doppler_hz=doppler_hz(rr, carrier_hz, mode, c=c),
                       elevation_rad=el, azimuth_rad=az, light_time_s=lt_s)
