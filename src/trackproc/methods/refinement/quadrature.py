"""The integral cost's quadrature (seed 004 eq. 14): composite Gauss-Legendre nodes over the parts of
the pass covered by data, their pseudo-sigmas, and the reception samples the orbit is evaluated at.
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.dynamics import timescales as ts
from trackproc.dynamics.geodesy import station_gcrf
from trackproc.models import observation as ob


def range_rate_samples(epoch, r_itrf_m, t_s, mode: str, eop=None):
    """``range_rate`` samples of a station at ``t_s`` (s from ``epoch``, reception times) as a
    :class:`~trackproc.models.observation.MeasurementSet` of link ``mode``: the station's GCRF
    position, velocity and acceleration at those UTC dates (as
    :func:`trackproc.pipeline.estimate.build_problem` does), for
    :func:`~trackproc.models.observation.evaluate` (values unset: zeros, unit sigmas)."""
    t_s = np.atleast_1d(np.asarray(t_s, float))
    epoch_jd = tuple(float(a) for a in ts.datetime64_to_jd_utc(np.datetime64(epoch, "ns")))
    jd1, jd2 = ts.add_seconds_utc(epoch_jd, t_s)
    track = station_gcrf(np.asarray(r_itrf_m, float), jd1, jd2, eop)
    k = t_s.size
    return ob.MeasurementSet(t_s=t_s.copy(), kind=np.full(k, "range_rate", dtype=object),
                             station=np.full(k, "station", dtype=object), pass_id=np.full(k, "", dtype=object),
                             observed=np.zeros(k), sigma=np.ones(k), r_st=track.r, v_st=track.v, a_st=track.a,
                             mode=np.full(k, mode, dtype=object))


def gauss_legendre(intervals, *, order: int = 16, panel_s: float = 60.0):
    """Composite Gauss-Legendre nodes and weights over ``intervals`` [(a, b), ...] (s).

    Each interval is cut into ``ceil((b - a) / panel_s)`` equal panels with ``order`` nodes
    each; every panel integrates polynomials of degree ``2 order - 1`` exactly. Returns
    ``(t_s (K,), w_s (K,))`` with ``Σ w_k g(t_k) ≈ ∫ g dt`` over the union of the intervals.
    Implements the quadrature of seed 004 eq. 14.

    >>> t, w = gauss_legendre([(0.0, 100.0)], order=4, panel_s=50.0)
    >>> round(float(w.sum()), 12), round(float(w @ t ** 3), 6)
    (100.0, 25000000.0)
    """
    if order < 1 or not panel_s > 0:
        raise ValueError(f"order must be >= 1 and panel_s > 0; found {order}, {panel_s}")
    x, wx = np.polynomial.legendre.leggauss(int(order))
    t_parts, w_parts = [], []
    for a, b in intervals:
        a, b = float(a), float(b)
        if not b > a:
            continue
        m = max(1, int(math.ceil((b - a) / panel_s - 1e-9)))
        edges = np.linspace(a, b, m + 1)
        mid = 0.5 * (edges[1:] + edges[:-1])
        half = 0.5 * (edges[1:] - edges[:-1])
        t_parts.append((mid[:, None] + half[:, None] * x[None, :]).ravel())
        w_parts.append((half[:, None] * wx[None, :]).ravel())
    if not t_parts:
        raise ValueError("no interval of positive length to integrate over")
    return np.concatenate(t_parts), np.concatenate(w_parts)


def covered_intervals(t_s, max_gap_s: float = 30.0, min_length_s: float = 1.0) -> list:
    """The parts of a pass covered by samples: ``[(a, b), ...]`` split at gaps longer than
    ``max_gap_s``; pieces shorter than ``min_length_s`` (isolated samples) are dropped."""
    t = np.sort(np.asarray(t_s, float))
    if t.size == 0:
        return []
    cut = np.flatnonzero(np.diff(t) > max_gap_s)
    starts = np.r_[0, cut + 1]
    ends = np.r_[cut, t.size - 1]
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends) if t[b] - t[a] >= min_length_s]


def pseudo_sigma(weights_s, sigma_ref: float, spacing_s: float) -> np.ndarray:
    """Pseudo-sigmas ``σ̄ √(Δt̄ / w_k)`` of the quadrature nodes: the whitened sum of squares is
    then ``I / (σ̄² Δt̄)``, the integral cost on the scale of the samples' χ² (module docstring)."""
    w = np.asarray(weights_s, float)
    if not (sigma_ref > 0 and spacing_s > 0) or np.any(w <= 0):
        raise ValueError("sigma_ref, spacing_s and the weights must be positive")
    return sigma_ref * np.sqrt(spacing_s / w)
