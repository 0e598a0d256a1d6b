"""Refinement of a stale orbit from one Doppler pass (seed 004): the integral cost, the circular-orbit
constraints by Lagrange multipliers, and the observability of one pass.

Seed 004 refines the state ``X_T = (x0, y0, z0, vx, vy, vz, r_ka)`` at the *traverse point* (where
the range-rate vanishes) by minimising the integral over the pass

    I(X_T) = ∫_T (Vr_LSQ(t) - Vr(X_T, t))² dt                                  (eq. 14)

of the squared difference between the smoothed range-rate polynomial ``Vr_LSQ = φ(t)ᵀ C``
(eq. 1, :mod:`trackproc.methods.smoothing`) and the range-rate of the orbit, computed in the
image domain (eqs. 6-13, :mod:`trackproc.dynamics.measurement_spectra`; one-way light time) or,
for a two-way (round-trip) pass, the seed's own ``Vr = c/(2 f0) f_D`` convention, by the
estimator's round-trip model on the same Taylor trajectory and STM (:class:`IntegralModel`),
optionally under the circular-orbit constraints

    f(X_T) = (|r|² - r_ka²,  |v|² - μ/r_ka,  r·v) = 0                              (eq. 5)

by Lagrange multipliers, ``L = I + λᵀ f`` (eqs. 15-17), with the gradients of ``Vr`` from the
first-order two-dimensional DT (eqs. 18-21), i.e. the sensitivity spectra of the Taylor engine
carried through the range and range-rate spectra.

Here:

* **Quadrature.** ``I`` is evaluated by composite Gauss-Legendre quadrature
  (:func:`gauss_legendre`) over the parts of the pass covered by data (:func:`covered_intervals`;
  a polynomial says nothing inside a long gap). With nodes ``t_k`` and weights ``w_k``,
  ``I ≈ Σ w_k (Vr_LSQ(t_k) - Vr(X, t_k))²``: a weighted least-squares problem in *pseudo-observations*
  ``Vr_LSQ(t_k)``. It is normalised to the scale of the samples' own χ², ``χ²_I = I / (σ̄² Δt̄)``
  (σ̄ the RMS sample sigma, Δt̄ the mean sample spacing: the integral of a curve sampled every Δt̄
  is Δt̄ times the sum), which is the pseudo-sigma ``σ_k = σ̄ √(Δt̄ / w_k)`` of
  :func:`pseudo_sigma`. That puts the integral cost and an a-priori constraint on one scale and
  lets the unconstrained problem be solved by the ordinary solver,
  :func:`trackproc.methods.least_squares.solve`.
* **Constraints (KKT).** :func:`solve_kkt` is Gauss-Newton with equality constraints: each step
  solves the KKT system of the linearised problem,

      [ 2 JᵀJ   Aᵀ ] [ δ ]   [ 2 Jᵀ b ]
      [  A      0  ] [ λ ] = [  -f    ],

  (J the whitened Jacobian, b the whitened residual, A = ∂f/∂X), by the null-space method: a QR
  factorisation ``Aᵀ = [Y Z] [R; 0]`` splits ``δ = Y p + Z q`` with ``Rᵀ p = -f`` (the
  constraint step) and ``q`` the least-squares solution of ``J Z q ≈ b - J Y p`` (by the same
  QR + SVD as the unconstrained solver: no normal matrix is formed). After each step the
  state is put back on the constraint surface by minimum-norm Newton steps, so every iterate is
  feasible and the cost alone decides whether a step is accepted (Levenberg-Marquardt damping
  of ``q`` otherwise). The multipliers follow from the first KKT row at the solution,
  ``Aᵀ λ = -∇χ²`` (least squares), and the covariance is that of the constrained estimate,
  ``Z (Zᵀ JᵀJ Z)⁻¹ Zᵀ`` (zero across the constraint surface).
* **Covariance of the integral estimate.** The pseudo-observations are a smoothed curve, not
  independent samples; :func:`sandwich_covariance` propagates the polynomial's coefficient
  covariance (from ``smooth``) through the linearised estimator:
  ``Cov = K J_dᵀ Σ⁻¹ Φ Σ_C Φᵀ Σ⁻¹ J_d K + K J_pᵀ J_p K`` (K the solver's (constrained) inverse
  normal matrix, J_d/J_p its data/a-priori rows, Φ the basis at the nodes).
* **Observability.** :func:`observability` reports the singular values of the whitened
  Jacobian and, with the bias parameters projected out, the state directions a pass determines
  and those it cannot see, in radial / along-track / cross-track terms (the weakest is a
  rotation of the orbit about the station's geocentric axis, which leaves every
  station-satellite distance unchanged).
* **Geodesic steps.** One pass leaves narrow, curved valleys in the cost; :func:`geodesic_retraction`
  adds the geodesic acceleration of Transtrum & Sethna to each Gauss-Newton step (one extra
  model evaluation) so that it follows them instead of creeping.
* **A default a-priori.** :func:`element_covariance` maps independent errors of non-singular
  orbital elements to a Cartesian covariance: tight in the period, loose along the track, as a
  stale catalogue orbit is.

Pure numpy on SI units (m, m/s, s); nothing here reads files or prints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.methods.least_squares import (Options, Solution, _iterate, prior_rows, _Problem, combination_text,
                                             whitened_svd)

__all__ = ["nonsingular_elements", "state_from_elements", "element_covariance", "ELEMENT_NAMES", "gauss_legendre",
           "covered_intervals", "pseudo_sigma", "circular_constraints", "constraint_scales", "IntegralModel",
           "KKTResult", "CachedModel", "geodesic_retraction", "solve_kkt", "circular_tolerance_covariance",
           "constraint_error_covariance", "sandwich_covariance", "observability", "Observability", "RTN_NAMES",
           "CONSTRAINT_NAMES", "profile_mixture", "PROFILE_NODES", "range_rate_samples"]

#: Names of the circular-orbit constraints (seed 004 eq. 5), in order.
CONSTRAINT_NAMES = ("|r|^2 - r_ka^2", "|v|^2 - mu/r_ka", "r.v")
#: State directions in the radial / along-track / cross-track frame.
RTN_NAMES = ("radial_m", "along_m", "cross_m", "radial_m_s", "along_m_s", "cross_m_s")
#: Feasibility reached by the restoration steps (relative to each constraint's scale).
FEASIBILITY_RTOL = 1e-14
_MAX_RESTORE = 30


# ----------------------------------------------------------------------------- quadrature

def range_rate_samples(epoch, r_itrf_m, t_s, mode: str, eop=None):
    """``range_rate`` samples of a station at ``t_s`` (s from ``epoch``, reception times) as a
    :class:`~trackproc.models.observation.MeasurementSet` of link ``mode``: the station's GCRF
    position, velocity and acceleration at those UTC dates (as
    :func:`trackproc.pipeline.estimate.build_problem` does), for
    :func:`~trackproc.models.observation.evaluate` (values unset: zeros, unit sigmas)."""
    from trackproc.dynamics import timescales as ts
    from trackproc.dynamics.geodesy import station_gcrf
    from trackproc.models import observation as ob

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
    ts, ws = [], []
    for a, b in intervals:
        a, b = float(a), float(b)
        if not b > a:
            continue
        m = max(1, int(math.ceil((b - a) / panel_s - 1e-9)))
        edges = np.linspace(a, b, m + 1)
        mid = 0.5 * (edges[1:] + edges[:-1])
        half = 0.5 * (edges[1:] - edges[:-1])
        ts.append((mid[:, None] + half[:, None] * x[None, :]).ravel())
        ws.append((half[:, None] * wx[None, :]).ravel())
    if not ts:
        raise ValueError("no interval of positive length to integrate over")
    return np.concatenate(ts), np.concatenate(ws)


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


# ----------------------------------------------------------------------------- constraints

def circular_constraints(x, mu_m3_s2: float, *, state_index=(0, 1, 2, 3, 4, 5), rka_index: int = 6):
    """Seed 004 eq. 5: ``f = (|r|² - r_ka², |v|² - μ/r_ka, r·v)`` and its Jacobian ``A`` (3, n).

    ``x`` holds the GCRF state at ``state_index`` (m, m/s) and ``r_ka`` (m) at ``rka_index``;
    every other entry (e.g. Doppler offsets) has zero partials.
    """
    x = np.asarray(x, float)
    idx = list(state_index)
    r, v, rka = x[idx[:3]], x[idx[3:]], float(x[rka_index])
    f = np.array([r @ r - rka * rka, v @ v - mu_m3_s2 / rka, r @ v])
    a = np.zeros((3, x.size))
    a[0, idx[:3]] = 2.0 * r
    a[0, rka_index] = -2.0 * rka
    a[1, idx[3:]] = 2.0 * v
    a[1, rka_index] = mu_m3_s2 / (rka * rka)
    a[2, idx[:3]] = v
    a[2, idx[3:]] = r
    return f, a


def constraint_scales(x, mu_m3_s2: float, *, state_index=(0, 1, 2, 3, 4, 5), rka_index: int = 6) -> np.ndarray:
    """Scales that make eq. 5 relative: ``(r_ka², μ/r_ka, |r| |v|)``.

    Implements seed 004 eq. 5 (the constraints' natural scales).
    """
    x = np.asarray(x, float)
    idx = list(state_index)
    rka = abs(float(x[rka_index]))
    return np.array([rka * rka, mu_m3_s2 / rka, np.linalg.norm(x[idx[:3]]) * np.linalg.norm(x[idx[3:]])])


# ----------------------------------------------------------------------------- orbital elements

#: Non-singular orbital elements (two-body, osculating): semi-major axis, eccentricity vector
#: components along the ascending node and 90 deg ahead of it in the plane, inclination, right
#: ascension of the ascending node, argument of latitude.
ELEMENT_NAMES = ("a_m", "ex", "ey", "i_rad", "raan_rad", "u_rad")


def nonsingular_elements(rv, mu_m3_s2: float) -> np.ndarray:
    """``(a, ex, ey, i, Ω, u)`` of a GCRF state (m, m/s); valid for e < 1 and i not near 0 or π."""
    rv = np.asarray(rv, float)
    r, v = rv[:3], rv[3:]
    rn = np.linalg.norm(r)
    h = np.cross(r, v)
    hn = np.linalg.norm(h)
    inc = math.acos(max(-1.0, min(1.0, h[2] / hn)))
    raan = math.atan2(h[0], -h[1])
    p_hat = np.array([math.cos(raan), math.sin(raan), 0.0])
    q_hat = np.cross(h / hn, p_hat)
    e_vec = ((v @ v - mu_m3_s2 / rn) * r - (r @ v) * v) / mu_m3_s2
    a = 1.0 / (2.0 / rn - (v @ v) / mu_m3_s2)
    u = math.atan2(r @ q_hat, r @ p_hat)
    return np.array([a, e_vec @ p_hat, e_vec @ q_hat, inc, raan, u])


def state_from_elements(q, mu_m3_s2: float) -> np.ndarray:
    """Inverse of :func:`nonsingular_elements`: the GCRF state (6,) of ``(a, ex, ey, i, Ω, u)``."""
    a, ex, ey, inc, raan, u = (float(x) for x in q)
    p = a * (1.0 - ex * ex - ey * ey)
    radius = p / (1.0 + ex * math.cos(u) + ey * math.sin(u))
    p_hat = np.array([math.cos(raan), math.sin(raan), 0.0])
    q_hat = np.array([-math.cos(inc) * math.sin(raan), math.cos(inc) * math.cos(raan), math.sin(inc)])
    r = radius * (math.cos(u) * p_hat + math.sin(u) * q_hat)
    w = math.sqrt(mu_m3_s2 / p)
    v = w * (-(math.sin(u) + ey) * p_hat + (math.cos(u) + ex) * q_hat)
    return np.concatenate([r, v])


#: Finite-difference steps of the element Jacobian.
_ELEMENT_STEPS = np.array([1.0, 1e-7, 1e-7, 1e-8, 1e-8, 1e-8])


def element_covariance(rv, mu_m3_s2: float, sigma_elements) -> np.ndarray:
    """GCRF covariance (6, 6) of a state whose non-singular elements have independent errors
    ``sigma_elements`` (:data:`ELEMENT_NAMES` order; m and rad): ``J diag(σ²) Jᵀ`` with
    ``J = ∂state/∂elements`` by central differences. It keeps what an orbit catalogue knows well
    (the period: semi-major axis) apart from what it knows poorly (the along-track phase)."""
    q0 = nonsingular_elements(rv, mu_m3_s2)
    jac = np.empty((6, 6))
    for k in range(6):
        dq = np.zeros(6)
        dq[k] = _ELEMENT_STEPS[k]
        jac[:, k] = (state_from_elements(q0 + dq, mu_m3_s2) - state_from_elements(q0 - dq, mu_m3_s2)) / (2 * dq[k])
    cov = jac @ np.diag(np.square(np.asarray(sigma_elements, float))) @ jac.T
    return 0.5 * (cov + cov.T)


# ----------------------------------------------------------------------------- geodesic steps

class CachedModel:
    """``model(x)`` remembering its last few results (the geodesic step re-uses the solver's)."""

    def __init__(self, model, size: int = 8):
        self.model = model
        self.size = size
        self._cache: dict = {}
        self.evaluations = 0

    def __call__(self, x):
        key = np.asarray(x, float).tobytes()
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) >= self.size:
                self._cache.pop(next(iter(self._cache)))
            hit = self.model(x)
            self.evaluations += 1
            self._cache[key] = hit
        return hit


def geodesic_retraction(model, sigma, scales, priors=(), *, fraction: float = 0.1, alpha: float = 0.75):
    """A step rule with geodesic acceleration (Transtrum & Sethna, arXiv:1201.5885).

    One pass of Doppler leaves the orbit in narrow, curved valleys of the cost (a slant range
    traded against radial and cross-track position; a rotation about the station's geocentric
    axis, which leaves every station-satellite distance unchanged): a straight Gauss-Newton step
    along the valley leaves it, is refused, and damped steps creep. The rule adds half the
    second-order correction ``a = -J⁺ h_vv``, with the directional second derivative of the
    model ``h_vv ≈ (2/f) ((h(x + f δ) - h(x))/f - J δ)`` (one extra model evaluation, ``f`` =
    ``fraction``), so the step follows the valley: ``x_new = x + δ + a/2``; the correction is
    dropped when ``|a| > alpha |δ|`` (scaled), where the expansion is not to be trusted.

    ``model`` (a :class:`CachedModel`, so that ``h(x), J(x)`` come from the solver's own
    evaluation), ``sigma`` the data sigmas, ``scales`` the parameter scales, ``priors`` the
    a-priori constraints (linear: no curvature). Returns ``retract(x, dx) -> x_new`` for
    :func:`trackproc.methods.least_squares.solve`.
    """
    sig = np.asarray(sigma, float)
    sc = np.asarray(scales, float)
    prior_a, _ = prior_rows(priors, sc.size, sc)

    def retract(x, dx):
        x = np.asarray(x, float)
        dx = np.asarray(dx, float)
        try:
            h0, jac = model(x)
            h1, _ = model(x + fraction * dx)
        except (ArithmeticError, ValueError, ProcessingError):
            return x + dx
        hvv = (2.0 / fraction) * ((np.asarray(h1) - h0) / fraction - jac @ dx)
        a_w = np.vstack([jac / sig[:, None] * sc[None, :], prior_a])
        rhs = np.r_[hvv / sig, np.zeros(prior_a.shape[0])]
        if not (np.all(np.isfinite(a_w)) and np.all(np.isfinite(rhs))):
            return x + dx
        acc = -np.linalg.lstsq(a_w, rhs, rcond=None)[0]
        if np.linalg.norm(acc) > alpha * np.linalg.norm(dx / sc):
            return x + dx
        return x + dx + 0.5 * sc * acc

    return retract


# ----------------------------------------------------------------------------- the integral model

class IntegralModel:
    """Range-rate of the orbit at the quadrature nodes and its gradient, from the DT spectra.

    ``model(x) -> (Vr (K,), ∂Vr/∂x (K, n))`` for ``x = (state at the epoch (6), biases..., [r_ka])``:
    the state is propagated by the Taylor (DT) engine with its sensitivity spectra
    (:func:`trackproc.dynamics.propagator.propagate`, ``stm=True``), and the range and range-rate
    spectra of the station (:func:`trackproc.dynamics.measurement_spectra.predict`: seed 004
    eqs. 7-13 with one-way light time) give ``Vr`` and, through the first-order sensitivities
    (eqs. 19-21), ``∂Vr/∂state``. A bias ``j`` adds ``coefficients[j] * x[6 + j]`` (e.g. ``-c/f``
    for a one-way Doppler offset in Hz, ``-c (t - t0)/f`` for its drift; ``-c/(2f)``,
    ``-c (t - t0)/(2f)`` two-way); trailing entries of ``x`` beyond those (``r_ka``) have no
    effect on ``Vr``.

    **Two-way** (``mode="two-way"``: a coherent round trip, the seed's own ``Vr = c/(2 f0) f_D``
    convention). The image-domain spectra follow the signal down one leg only, so a two-way
    ``Vr`` is the estimator's round-trip model instead:
    :func:`trackproc.models.observation.evaluate` on ``range_rate`` samples with mode
    ``two-way`` at the nodes — the mean of the up- and down-leg rates, both light times solved
    on the same Taylor trajectory (its dense output, GCRF), the station in GCRF
    (:func:`trackproc.models.measurements.station_gcrf`, with its acceleration, at the nodes'
    UTC dates, as :func:`trackproc.pipeline.estimate.build_problem` does). ``∂Vr/∂state`` is
    then the leg partials times the Taylor engine's state transition matrix (its first-order
    sensitivity spectra, eqs. 19-21 in spirit) through both light times (observation eqs. 6,
    11-13): analytic, not finite differences. The node set-up (station track) is built once,
    on the first evaluation.

    Parameters
    ----------
    epoch : datetime64 — the epoch of the state (the traverse point).
    frame : QuasiInertialFrame — the integration frame (the estimation problem's).
    station : :class:`~trackproc.dynamics.measurement_spectra.StationModel` built on ``epoch``
        and ``frame`` (two-way: its ITRF position ``r_itrf_m`` is used).
    t_s : (K,) node times, SI s from the epoch (reception times).
    bias_coefficients : list of (K,) arrays, one per bias parameter.
    force, eop, range_rate_model : as elsewhere.
    mode : ``"one-way"`` (default) or ``"two-way"``.
    """

    def __init__(self, epoch, frame, station, t_s, bias_coefficients=(), *, force: str = "j2", eop=None,
                 range_rate_model: str = "doppler", n_extra: int = 0, mode: str = "one-way"):
        if mode not in ("one-way", "two-way"):
            raise ValueError(f"unknown link mode {mode!r}; expected 'one-way' or 'two-way'")
        self.epoch = epoch
        self.frame = frame
        self.station = station
        self.t_s = np.asarray(t_s, float)
        self.bias = [np.asarray(c, float) for c in bias_coefficients]
        self.force = force
        self.eop = eop
        self.range_rate_model = range_rate_model
        self.n_extra = int(n_extra)
        self.mode = mode
        self.evaluations = 0
        self._nodes = None

    @property
    def n_parameters(self) -> int:
        return 6 + len(self.bias) + self.n_extra

    def trajectory(self, x):
        from trackproc.dynamics import propagator

        span = [float(self.t_s.min()) - 1.0, float(self.t_s.max())]
        return propagator.propagate(x[:3], x[3:6], self.epoch, span, force=self.force, stm=True, frame=self.frame,
                                    eop=self.eop).raise_for_outcome()

    def node_measurements(self):
        """The nodes as ``range_rate`` samples of the link (:func:`range_rate_samples`, built once)."""
        if self._nodes is None:
            self._nodes = range_rate_samples(self.epoch, self.station.r_itrf_m, self.t_s, self.mode, self.eop)
        return self._nodes

    def _state_part(self, x):
        """``(Vr (K,), ∂Vr/∂state (K, 6))`` of the link (one-way: DT spectra; two-way: round trip)."""
        traj = self.trajectory(x)
        if self.mode == "two-way":
            from trackproc.models import observation as ob

            value, jac, _ = ob.evaluate(self.node_measurements(), traj, n_state_params=6, n_columns=6,
                                        range_rate_model=self.range_rate_model)
            return value, jac
        from trackproc.dynamics import measurement_spectra as ms

        pred = ms.predict(traj, self.station, self.t_s, range_rate_model=self.range_rate_model)
        return pred.range_rate_m_s.copy(), pred.d_range_rate_d_state

    def __call__(self, x):
        x = np.asarray(x, float)
        try:
            value, d_state = self._state_part(x)
        except ValueError as exc:
            raise ArithmeticError(str(exc)) from None
        jac = np.zeros((self.t_s.size, x.size))
        jac[:, :6] = d_state
        for j, coef in enumerate(self.bias):
            value += coef * x[6 + j]
            jac[:, 6 + j] = coef
        self.evaluations += 1
        return value, jac


# ----------------------------------------------------------------------------- constrained solver

@dataclass
class KKTResult:
    """A solution under equality constraints (:func:`solve_kkt`).

    ``solution`` (a :class:`~trackproc.methods.least_squares.Solution`; its covariance is the
    constrained one, singular across the constraint surface), ``multipliers`` λ of
    ``L = χ² + λᵀ f`` (seed 004 eq. 16; units: cost per unit of each constraint),
    ``constraints`` f at the solution, ``relative`` f divided by :func:`constraint_scales`,
    ``stationarity`` the free Gauss-Newton step left at the solution, in formal sigmas (0 at a
    KKT point: ``∇χ² + Aᵀλ = 0``),
    ``restorations`` minimum-norm Newton steps taken to stay feasible, ``sensitivity`` (n, m)
    ``dx̂/dε``: how the solution moves if the constraints were ``f = ε`` instead of 0 (for the
    covariance of a constraint that holds only approximately, :func:`constraint_error_covariance`).
    """

    solution: Solution
    multipliers: np.ndarray
    constraints: np.ndarray
    relative: np.ndarray
    stationarity: float
    restorations: int = 0
    null_space_dim: int = 0
    sensitivity: Optional[np.ndarray] = None


def _null_space(a_scaled):
    """``Y`` (n, m), ``Z`` (n, n - m), ``R`` (m, m) with ``A_sᵀ = Y R`` (QR of the constraint Jacobian)."""
    m = a_scaled.shape[0]
    q, r = np.linalg.qr(a_scaled.T, mode="complete")
    rr = r[:m, :m]
    if np.any(np.abs(np.diag(rr)) <= 1e-13 * max(np.abs(np.diag(rr)).max(), 1e-300)):
        raise ProcessingError("the constraints are degenerate at this point (their Jacobian is rank deficient)")
    return q[:, :m], q[:, m:], rr


def solve_kkt(model: Callable[[np.ndarray], tuple], x0, observed, sigma, *, names: Sequence[str],
              constraints: Callable[[np.ndarray], tuple], constraint_scale: Callable[[np.ndarray], np.ndarray],
              scales=None, priors=(), periodic=None, options: Options | None = None, retract=None) -> KKTResult:
    """Minimise ``Σ ((y - h(x))/σ)² + prior terms`` subject to ``f(x) = 0`` (seed 004 eqs. 15-17).

    Gauss-Newton on the KKT system of each linearised step, solved by the null-space method
    (module docstring); every iterate is restored onto ``f = 0`` by minimum-norm Newton steps;
    Levenberg-Marquardt damping of the free step; the k-sigma editing, stopping rules and failure
    reports are those of :func:`trackproc.methods.least_squares.solve` (the same problem and iterations).

    ``constraints(x) -> (f (m,), A (m, n))``; ``constraint_scale(x) -> (m,)`` positive scales
    making ``f`` relative (feasible when every ``|f| / scale < 1e-14``); ``retract`` as in
    :func:`~trackproc.methods.least_squares.solve` (applied before the restoration).
    Raises :class:`ProcessingError` on failure.
    """
    opt = options or Options()
    x = np.asarray(x0, float).copy()
    n = x.size
    names = list(names)
    prob = _Problem(model, n, observed, sigma, scales=scales, priors=priors, periodic=periodic, clip=opt.clip)
    scales = prob.scales
    restorations = 0

    def restore(xv):
        nonlocal restorations
        for _ in range(_MAX_RESTORE):
            f, a = constraints(xv)
            if np.all(np.abs(f) <= FEASIBILITY_RTOL * constraint_scale(xv)):
                return xv
            step = np.linalg.lstsq(a * scales[None, :], -f, rcond=None)[0]
            xv = xv + scales * step
            restorations += 1
        f, _ = constraints(xv)
        rel = np.abs(f) / constraint_scale(xv)
        if np.all(rel < 1e-10):
            return xv
        raise ArithmeticError(f"cannot satisfy the constraints (relative residual {rel.max():.3g})")

    def reduced(jac, r, xv, mask, it):
        f, ac = constraints(xv)
        yb, zb, rr = _null_space(ac * scales[None, :])
        p = -np.linalg.solve(rr.T, f)
        a, b = prob.system(jac, r, xv, mask, it)
        ub, s, vt = whitened_svd(a @ zb, b - a @ (yb @ p))
        if s.size < zb.shape[1] or s[-1] <= opt.rank_rtol * s[0]:
            weak = combination_text(zb @ vt[-1], names) if s.size else ""
            raise ProcessingError(
                f"rank-deficient problem under the constraints (condition number "
                f"{s[0] / s[-1] if s.size and s[-1] > 0 else math.inf:.3g}); unobservable combination of the "
                f"scaled parameters: {weak}", {"iteration": it, "singular_values": s.tolist()})
        return yb, zb, rr, p, ub, s, vt

    def linearise(jac, r, xv, mask, it):
        yb, zb, _, p, ub, s, vt = reduced(jac, r, xv, mask, it)
        return ub, s, vt, lambda q: yb @ p + zb @ q                 # δ = Y p + Z q

    def trial(xv, xi):
        try:
            return restore(prob.step(xv, xi, retract))
        except (ArithmeticError, ProcessingError, ValueError):
            return None

    def check_counts(mask):
        if int((~mask).sum()) + prob.n_prior < n - 3:
            raise ProcessingError(f"too few measurements: {int((~mask).sum())} kept for {n} parameters")

    x, h, jac = prob.start(x, prepare=restore)
    if not np.all(np.isfinite(h)):
        raise ProcessingError("the model gives non-finite values at the initial values")
    r = prob.residuals(h)
    mask = prob.edit(r, np.zeros(prob.nobs, bool))
    run = _iterate(prob, opt, x, h, jac, r, mask, stable=not mask.any(), linearise=linearise, trial=trial,
                   check=check_counts, tag=" (constrained)")
    if not run.converged:
        history = run.history
        raise ProcessingError(
            f"did not converge in {opt.max_iterations} iterations under the constraints (cost {history[-2]:.6g} -> "
            f"{history[-1]:.6g}); try --max-iterations, a better --initial state, or drop --circular",
            {"iterations": run.iterations, "cost_history": history})

    # covariance, multipliers and stationarity at the solution
    x = run.x
    yb, zb, rr, _, ub, s, vt = reduced(run.jac, run.r, x, run.mask, run.iterations)
    inner = (vt.T / s ** 2) @ vt
    f, ac = constraints(x)
    sol = prob.solution(names, run, zb @ inner @ zb.T, s, free=n - f.size, constrained=True)
    a, b = prob.system(run.jac, run.r, x, run.mask, run.iterations)
    grad = -2.0 * a.T @ b                                    # ∇χ² in the scaled parameters
    lam = np.linalg.lstsq((ac * scales[None, :]).T, -grad, rcond=None)[0]
    # stationarity: the free Gauss-Newton step left at the solution, in formal sigmas
    sig_q = np.sqrt(np.sum((vt / s[:, None]) ** 2, axis=0))
    stationarity = float(np.max(np.abs(vt.T @ (ub / s)) / sig_q))
    # dξ/dε: the constraint step Y R⁻ᵀ δε, minus the free directions' readjustment
    a_y = yb @ np.linalg.inv(rr.T)
    sens = a_y - zb @ (inner @ (zb.T @ (a.T @ (a @ a_y))))
    return KKTResult(solution=sol, multipliers=lam, constraints=f, relative=f / constraint_scale(x),
                     stationarity=stationarity, restorations=restorations, null_space_dim=int(zb.shape[1]),
                     sensitivity=sens * scales[:, None])


def circular_tolerance_covariance(x, mu_m3_s2: float, eccentricity: float, *, state_index=(0, 1, 2, 3, 4, 5)):
    """Covariance (3, 3) of the constraint values of eq. 5 for an orbit that is circular only to
    ``eccentricity``: with r_ka = |r| the first is exact; ``|v|² - μ/r = (μ/r) e cos E`` and
    ``r·v = √(μ r) e sin E`` to first order in e, for an unknown eccentric anomaly E (variance e²/2).

    Implements seed 004 eq. 5 (as soft constraints).
    """
    x = np.asarray(x, float)
    r = float(np.linalg.norm(x[list(state_index)[:3]]))
    e2 = float(eccentricity) ** 2 / 2.0
    return np.diag([0.0, (mu_m3_s2 / r) ** 2 * e2, mu_m3_s2 * r * e2])


def constraint_error_covariance(sensitivity, constraint_covariance) -> np.ndarray:
    """``D Σ_ε Dᵀ``: the covariance a constraint that holds only to ``Σ_ε`` adds to the solution
    (D = dx̂/dε from :func:`solve_kkt`)."""
    d = np.asarray(sensitivity, float)
    out = d @ np.asarray(constraint_covariance, float) @ d.T
    return 0.5 * (out + out.T)


# ----------------------------------------------------------------------------- covariance of the integral

def sandwich_covariance(solution: Solution, sigma_nodes, design_nodes, coefficient_covariance,
                        priors=(), *, rows=None) -> np.ndarray:
    """Covariance of the integral estimate from the smoothing polynomial's coefficient covariance.

    The estimate is a function of the polynomial coefficients C (and of the a-priori centre);
    linearised, ``δξ = K (J_dᵀ Σ⁻¹ Φ δC + J_pᵀ δb_p)`` with ``K`` the solver's covariance of the
    scaled parameters (the constrained one under constraints), ``J_d`` the whitened data rows,
    ``Σ = diag(σ_k)`` the pseudo-sigmas, ``Φ`` (K, m) the basis at the nodes in the units of the
    pseudo-observations, ``Cov(C)`` the coefficient covariance and ``J_p`` the whitened a-priori
    rows (``δb_p ~ N(0, I)``). Returns the physical covariance (n, n).
    """
    sol = solution
    scales = np.asarray(sol.scales, float)
    n = scales.size
    k_scaled = np.asarray(sol.covariance_scaled, float)
    sig = np.asarray(sigma_nodes, float)
    jd = sol.jacobian / sig[:, None] * scales[None, :]
    b = jd.T @ (np.asarray(design_nodes, float) / sig[:, None])          # (n, m)
    middle = b @ np.asarray(coefficient_covariance, float) @ b.T
    if priors:
        pa, _ = prior_rows(priors, n, scales)
        middle = middle + pa.T @ pa
    cov_scaled = k_scaled @ middle @ k_scaled
    cov = cov_scaled * np.outer(scales, scales)
    return 0.5 * (cov + cov.T)


# ----------------------------------------------------------------------------- observability

@dataclass
class Observability:
    """What one pass determines: see :func:`observability`.

    ``singular_values``: of the whitened Jacobian of every estimated parameter, the state columns
    in units of the reference sigma and the others in their drivers' scales; ``names`` its
    columns. ``state_singular_values`` (6,): of the state part after projecting the other
    parameters out, in units of the reference (a-priori) sigma: ``s > 1`` means the pass alone
    determines that direction better than the reference; ``gain`` ``1/√(1 + s²)`` is the
    posterior/prior sigma ratio along it (with the reference as the prior). ``directions`` (6, 6):
    rows are the corresponding state directions, RTN components (m, m/s) of a one-reference-sigma
    perturbation; ``unobservable`` the indices with ``s < threshold``; ``reference_sigma`` the
    RTN sigmas of the reference (6,); ``posterior_sigma_rtn``: the solution's RTN sigmas;
    ``rotation_alignment``: |cos| between the weakest direction and a rotation of the orbit about
    the station's geocentric axis (which leaves every station-satellite distance unchanged), in
    the reference metric (1 = that rotation is what the pass cannot see).
    """

    names: list
    singular_values: np.ndarray
    state_singular_values: np.ndarray
    gain: np.ndarray
    directions: np.ndarray
    unobservable: list
    reference: str
    reference_sigma_rtn: np.ndarray
    posterior_sigma_rtn: np.ndarray
    threshold: float = 1.0
    rotation_alignment: Optional[float] = None
    notes: list = field(default_factory=list)
    #: (6, 6) GCRF: column i is direction i (``L vᵢ``); ``dual`` row i picks its coefficient (``vᵢᵀ L⁻¹``)
    basis: Optional[np.ndarray] = None
    dual: Optional[np.ndarray] = None
    #: the refinement's correction (refined - stale) split by :meth:`split`, RTN (m, m/s)
    correction_rtn: Optional[dict] = None

    def split(self, difference) -> tuple[np.ndarray, np.ndarray]:
        """``(seen, unseen)``: a GCRF state difference (6,) (an error, a correction) split into
        the part along the directions the pass determines and the part along those it cannot
        see (:attr:`unobservable`); ``seen + unseen = difference``. The split is the one of the
        report (the reference metric), so the unseen part is what only the a-priori can bound."""
        d = np.asarray(difference, float)
        weak = list(self.unobservable)
        unseen = self.basis[:, weak] @ (self.dual[weak] @ d) if weak else np.zeros(6)
        return d - unseen, unseen

    def direction_text(self, i: int, threshold: float = 0.2) -> str:
        """``+9.9 km along -1.3 km radial ...``: the main RTN components of direction ``i``."""
        d = self.directions[i]
        k = int(np.argmax(np.abs(d / np.maximum(self.reference_sigma_rtn, 1e-300))))
        if d[k] < 0:
            d = -d
        weight = np.abs(d) / np.maximum(self.reference_sigma_rtn, 1e-300)
        weight = weight / max(weight.max(), 1e-300)
        parts = []
        for j in np.argsort(-weight):
            if weight[j] < threshold:
                continue
            label = RTN_NAMES[j].replace("_m_s", " velocity").replace("_m", "")
            value = d[j]
            if j < 3:
                parts.append(f"{value / 1e3:+.3g} km {label}")
            else:
                parts.append(f"{value:+.3g} m/s {label}")
        return " ".join(parts)

    def as_dict(self) -> dict:
        return {
            "reference": self.reference,
            "threshold": self.threshold,
            "singular_values": {"parameters": list(self.names), "values": self.singular_values.tolist()},
            "state_singular_values": self.state_singular_values.tolist(),
            "posterior_to_reference_sigma": self.gain.tolist(),
            "directions_rtn": [dict(zip(RTN_NAMES, row.tolist())) for row in self.directions],
            "directions_text": [self.direction_text(i) for i in range(len(self.directions))],
            "unobservable": [self.direction_text(i) for i in self.unobservable],
            "reference_sigma_rtn": dict(zip(RTN_NAMES, self.reference_sigma_rtn.tolist())),
            "weakest_vs_rotation_about_station_axis": self.rotation_alignment,
            "posterior_sigma_rtn": dict(zip(RTN_NAMES, self.posterior_sigma_rtn.tolist())),
            "correction_rtn": self.correction_rtn,
            "notes": list(self.notes),
        }


#: Gauss-Hermite nodes per unseen direction of :func:`profile_mixture`.
PROFILE_NODES = 5


def profile_mixture(solve_fixed: Callable[[float], tuple], x_hat, sigma: float, nodes: int = PROFILE_NODES):
    """Covariance about ``x_hat`` of a posterior that is curved along one direction.

    ``solve_fixed(target) -> (x_k, C_k)``: the solution with that direction's coordinate held
    at ``target`` and its covariance conditional on it; ``sigma`` the coordinate's linear
    posterior sigma. With the probabilists' Gauss-Hermite nodes ``t_k`` and weights ``w_k``
    (normalised), ``Σ w_k (C_k + (x_k - x̂)(x_k - x̂)ᵀ)`` at ``target = t_k σ``: equal to the linear
    covariance when the problem is linear, and it carries the spread of the valley the
    estimate slides along when it is not (one pass: the rotation about the station's axis).
    """
    t, w = np.polynomial.hermite_e.hermegauss(nodes)
    w = w / w.sum()
    x_hat = np.asarray(x_hat, float)
    out = np.zeros((x_hat.size, x_hat.size))
    for tk, wk in zip(t, w):
        x_k, c_k = solve_fixed(float(tk) * sigma)
        d = np.asarray(x_k, float) - x_hat
        out += wk * (np.asarray(c_k, float) + np.outer(d, d))
    return out


def observability(jacobian, sigma, names, rtn, reference_covariance, posterior_covariance, *,
                  other_scales=None, reference: str = "", threshold: float = 1.0,
                  station_axis=None, state=None) -> Observability:
    """Observability of the state from one pass.

    ``jacobian`` (N, n) of the model at the solution (state x..vz in the first 6 columns, GCRF),
    ``sigma`` (N,) the data sigmas, ``rtn`` (6, 6) the map of GCRF state errors to RTN ones
    (:func:`trackproc.dynamics.rtn.rtn_jacobian` with ``rotating=False``),
    ``reference_covariance`` (6, 6) GCRF: the a-priori covariance (or a nominal one) that sets
    the units; ``posterior_covariance`` (6, 6) GCRF; ``other_scales`` (n - 6,) column scales
    of the other parameters for the plain singular values.

    The state information ``Λ = J_sᵀ (I - P_b) J_s`` (``P_b`` the projector on the bias columns:
    the biases are estimated, so only what they cannot absorb informs the state) is whitened by
    the reference, ``M = Lᵀ Λ L`` with ``reference = L Lᵀ``; its eigenvalues are the squared
    state singular values and ``L u`` the directions (rotated to RTN).
    """
    jw = np.asarray(jacobian, float) / np.asarray(sigma, float)[:, None]
    n = jw.shape[1]
    ref = np.asarray(reference_covariance, float)
    chol = np.linalg.cholesky(ref)
    js = jw[:, :6] @ chol
    scales_other = np.ones(n - 6) if other_scales is None else np.asarray(other_scales, float)
    if n > 6:
        jb = jw[:, 6:] * scales_other[None, :]
        qb, rb = np.linalg.qr(jb)
        keep = np.abs(np.diag(rb)) > 1e-12 * max(np.abs(np.diag(rb)).max(), 1e-300)
        qb = qb[:, keep]
        js_proj = js - qb @ (qb.T @ js)
        full = np.hstack([js, jb])
    else:
        js_proj = js
        full = js
    sv_full = np.linalg.svd(full, compute_uv=False)
    _, s, vt = np.linalg.svd(js_proj, full_matrices=False)
    big = np.asarray(rtn, float)
    directions = (big @ chol @ vt.T).T                           # rows: RTN of L u_i
    ref_rtn = np.sqrt(np.clip(np.diag(big @ ref @ big.T), 0.0, None))
    post_rtn = np.sqrt(np.clip(np.diag(big @ np.asarray(posterior_covariance, float) @ big.T), 0.0, None))
    weak = [i for i in range(6) if s[i] < threshold]
    align = None
    if station_axis is not None and state is not None:
        k = np.asarray(station_axis, float) / np.linalg.norm(station_axis)
        st = np.asarray(state, float)
        t_w = np.linalg.solve(chol, np.r_[np.cross(k, st[:3]), np.cross(k, st[3:6])])
        align = float(abs(vt[-1] @ t_w) / np.linalg.norm(t_w))
    return Observability(names=list(names), singular_values=sv_full, state_singular_values=s,
                         gain=1.0 / np.sqrt(1.0 + s * s), directions=directions, unobservable=weak,
                         reference=reference, reference_sigma_rtn=ref_rtn, posterior_sigma_rtn=post_rtn,
                         threshold=threshold, rotation_alignment=align, basis=chol @ vt.T,
                         dual=vt @ np.linalg.inv(chol))
