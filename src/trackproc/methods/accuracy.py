"""Accuracy of a predicted trajectory: mean, variance and correlation from the initial uncertainty.

Pure functions on numpy arrays, SI units (m, m/s, s). Three independent ways to the same
second moments, so that each checks the others:

1. **The image-domain method of seed 000** (eqs. 12-25). The random initial errors make the
   discretes of the trajectory's differential spectrum random variables, ``X(K, V)``. A
   *random spectrum* is stored as an array ``(..., 1 + m, n)``: slot 0 holds the discretes at
   ``V = 0`` and slot ``j`` their derivative with respect to the random variable ``v_j``
   (``j = 1..m``), so that ``X(K, V) = X(K, 0) + sum_j dX(K)/dv_j v_j``. For zero-mean V with
   covariance C (seed 000 eqs. 7-8; correlated errors are first reduced to uncorrelated
   normalised variables ``xi`` by ``V = L xi``, ``L L^T = C``, as seed 000 prescribes after
   eq. 5, see :func:`normalizing_factor`):

   * mean discretes ``m_x(K) = E[X(K, V)] = X(K, 0)``                          (eqs. 17-20)
   * ``Q(K, t1, t2) = X(., t1) * X(., t2)`` (Cauchy product) and its mean     (eqs. 21-23)
   * ``R_x(K, t1, t2) = m_q(K) - (m_x(., t1) * m_x(., t2))(K)
     = sum_j (W_j(., t1) * W_j(., t2))(K)``, ``W = dX/dV L``                     (eq. 24)
   * ``R_x(t1, t2) = sum_K R_x(K, t1, t2)``, ``D_x(t) = R_x(t, t)``           (eq. 25)

   The subtraction of eq. 24 is carried out algebraically (the ``m * m`` terms cancel
   exactly for spectra affine in V): done numerically it would subtract two numbers of the
   size of ``|r|^2 ~ 5e13 m^2`` to get ``sigma^2 ~ 1e4 m^2`` and lose seven digits. The
   Cauchy products are complete (``n1 + n2 - 1`` discretes), as in the paper's eqs. 33-34,
   whose ``t^6`` terms come from four discretes; their sum is then exactly the product of
   the two series' sums.

   The method is exact for models linear in the random variables (the seed's worked example,
   :func:`seed000_spectra`). For the nonlinear two-body / J2 motion the discretes are not
   affine in V; their first-order expansion ``X(K, 0) + dX(K)/dV V`` is what the DT engine's
   sensitivity spectra are (seed 004 eqs. 19-21 to first order, :mod:`trackproc.dynamics.taylor`),
   so :func:`state_spectra` + :func:`correlation` give the first-order (linear) covariance.
   Each step of the engine has its own expansion point (its start ``t_s``) and the scale
   ``H = t - t_s`` takes the place of the paper's ``H = t - t0``; the random part of every
   step's discretes still refers to the same initial errors V, so R(t1, t2) across steps is
   the same Cauchy product of two spectra.

2. **Linear covariance propagation** ``P(t) = Phi(t) P0 Phi(t)^T`` with the engine's state
   transition matrix (:func:`stm_covariance`). Mathematically the same first-order moments as
   1 (the sum over K of the sensitivity discretes is Phi): they agree to round-off.

3. **Monte Carlo**: N initial states drawn from ``N(x0, P0)`` (:func:`sample_initial_states`)
   propagated by the engine's batch mode, and their sample covariance
   (:func:`sample_covariance`). Includes every nonlinearity; agrees with 1 and 2 within its
   statistical bound (:func:`monte_carlo_bounds`) while the errors stay small enough for the
   first order to hold.

Frames: covariances of the six state components ``(x, y, z, vx, vy, vz)`` in an inertial
frame; :func:`rtn_rotation` resolves them along radial / along-track / cross-track axes of
the nominal orbit, and :func:`range_range_rate_jacobian` maps them to a ground station's
range and range-rate.
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.dynamics import spectra as sp
from trackproc.dynamics.rtn import rtn_jacobian, rtn_rotation, to_rtn  # noqa: F401  (re-exported)

__all__ = [
    "normalizing_factor", "mean_spectrum", "correlation_spectrum", "correlation", "variance",
    "seed000_spectra", "seed000_variance_exact", "seed000_velocity_variance_exact",
    "seed000_statistics", "seed000_enough_discretes", "seed000_velocity_weight",
    "state_spectra", "spectral_covariance", "spectral_cross_covariance", "spectral_factors",
    "stm_covariance", "stm_cross_covariance",
    "sample_initial_states", "sample_covariance", "monte_carlo_bounds", "covariance_sd",
    "rtn_rotation", "rtn_jacobian", "to_rtn", "range_range_rate_jacobian", "observable_covariance",
    "sigmas", "correlation_coefficients",
]


# =========================================================================== seed 000, generic

def normalizing_factor(cov) -> np.ndarray:
    """A factor ``L`` with ``L L^T = cov``: ``V = L xi`` with uncorrelated normalised ``xi``.

    Seed 000, the paragraph after eq. 5 and eq. 7: correlated random variables are reduced by
    a linear transform to uncorrelated ones with zero mean and unit variance. Built from the
    symmetric eigen-decomposition ``U diag(lambda) U^T`` as ``U diag(sqrt(lambda))``, so a
    positive *semi*-definite covariance (an unobservable direction, a parameter held fixed)
    is accepted; eigenvalues below ``-1e-10`` times the largest raise ``ValueError``, smaller
    negative ones (round-off) count as zero.
    """
    c = np.asarray(cov, dtype=float)
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        raise ValueError(f"a covariance must be a square matrix; found shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError("the covariance must be finite")
    c = 0.5 * (c + c.T)
    # scale to a correlation-like matrix first so that m^2 and m^2/s^2 blocks are treated alike
    d = np.sqrt(np.clip(np.diag(c), 0.0, None))
    s = np.where(d > 0, d, 1.0)
    lam, u = np.linalg.eigh(c / np.outer(s, s))
    top = max(float(lam.max(initial=0.0)), 0.0)
    if lam.size and lam.min() < -1e-10 * max(top, 1.0):
        raise ValueError(f"the covariance is not positive semi-definite (eigenvalue {lam.min():.3g} "
                         "of its correlation matrix)")
    return s[:, None] * (u * np.sqrt(np.clip(lam, 0.0, None)))


def mean_spectrum(spec) -> np.ndarray:
    """Mean discretes ``m_x(K) = E[X(K, V)]`` of a random spectrum ``(..., 1 + m, n)``.

    Seed 000 eqs. 17-20 (and 19-20 for the two scales ``H1 = t1``, ``H2 = t2``): for a spectrum
    affine in zero-mean random variables the expectation is the value at ``V = 0``, slot 0.
    """
    s = np.asarray(spec, dtype=float)
    return s[..., 0, :]


def _weights(spec, cov):
    """The random part ``dX/dV L`` of a random spectrum: (..., m', n)."""
    s = np.asarray(spec, dtype=float)
    d = s[..., 1:, :]
    if cov is None:
        return d
    lo = normalizing_factor(cov)
    if lo.shape[0] != d.shape[-2]:
        raise ValueError(f"the covariance is {lo.shape[0]} x {lo.shape[0]} but the spectrum carries "
                         f"{d.shape[-2]} random variables")
    return np.einsum("...jn,jk->...kn", d, lo)


def correlation_spectrum(spec1, spec2=None, cov=None) -> np.ndarray:
    """Correlation spectrum ``R_x(K, t1, t2)`` of two random spectra (seed 000 eqs. 21-24).

    Parameters
    ----------
    spec1 : array ``(..., A, 1 + m, n1)``
        Random spectrum of A components at the scale ``H1`` (e.g. the state at t1): slot 0 the
        discretes at V = 0, slots 1..m their derivatives with respect to ``v_1..v_m``.
    spec2 : array ``(..., B, 1 + m, n2)``, optional
        The same at ``H2`` (default ``spec1``: the variance spectrum).
    cov : array ``(m, m)``, optional
        Covariance of V (zero mean). Default: the identity (V already normalised, eq. 7).

    Returns
    -------
    array ``(..., A, B, n1 + n2 - 1)``
        ``R(K) = m_q(K) - (m_x(., t1) * m_x(., t2))(K) = sum_j (W_aj * W_bj)(K)``, complete
        Cauchy products (docs/equations.md, notation: "product") of the normalised random parts
        ``W = dX/dV L``. Exact for spectra affine in V (see the module docstring on eq. 24).
    """
    w1 = _weights(spec1, cov)
    w2 = w1 if spec2 is None else _weights(spec2, cov)
    n1, n2 = w1.shape[-1], w2.shape[-1]
    n = n1 + n2 - 1
    lead = np.broadcast_shapes(w1.shape[:-3], w2.shape[:-3])
    a, b = w1.shape[-3], w2.shape[-3]
    out = np.zeros(lead + (a, b, n))
    # (W1_a * W2_b)(K) summed over the random variables j: one contraction per discrete of W1
    for l in range(n1):
        out[..., l:l + n2] += np.einsum("...aj,...bjn->...abn", w1[..., l], w2)
    return out


def correlation(spec1, spec2=None, cov=None) -> np.ndarray:
    """``R_x(t1, t2) = sum_K R_x(K, t1, t2)`` (seed 000 eq. 25): ``(..., A, B)``.

    With ``spec2 = None`` this is the covariance matrix of the A components at one time, whose
    diagonal is the variance ``D_x(t) = R_x(t, t)``.
    """
    return correlation_spectrum(spec1, spec2, cov).sum(axis=-1)


def variance(spec, cov=None) -> np.ndarray:
    """``D_x(t) = R_x(t, t)`` of every component of ``spec`` ``(..., A, 1 + m, n)``: ``(..., A)``."""
    w = _weights(spec, cov)
    n = w.shape[-1]
    out = np.zeros(w.shape[:-3] + (w.shape[-3], 2 * n - 1))
    for l in range(n):
        out[..., l:l + n] += np.einsum("...aj,...ajn->...an", w[..., l], w)
    return out.sum(axis=-1)


# =========================================================================== seed 000 worked example

def seed000_spectra(t_s, n_rad_s: float, n_discretes: int, *, x0_m: float = 0.0, g0_m_s: float = 0.0,
                    restart_s: float | None = None) -> np.ndarray:
    """Random spectra of the seed's worked example (seed 000 eqs. 29-31), scale ``H = t``.

    The model is one axis of a circular orbit with constant radius, ``x'' = -n^2 x`` with
    ``n^2 = mu / r^3`` (eq. 29), ``x(0) = x0 - v1``, ``x'(0) = g0 - v2``; its P-model (eq. 30)

        X(K+1) = H/(K+1) G(K),   G(K+1) = -n^2 H/(K+1) X(K)

    is linear, so the discretes are affine in ``V = (v1, v2)`` and the image-domain statistics
    are exact. The initial discretes carry the random variables: ``X(0) = [x0, -1, 0]``,
    ``G(0) = [g0, 0, -1]`` in the slots ``[value, d/dv1, d/dv2]``.

    Parameters
    ----------
    t_s : array ``(M,)``
        Times since the initial epoch, s (any sign).
    n_rad_s : float
        Mean motion ``sqrt(mu / r^3)``, rad/s.
    n_discretes : int
        Number of discretes K = 0..N-1 of each spectrum (the paper takes 4 and 6).
    x0_m, g0_m_s : float
        Mean initial position and velocity (they do not enter the variance).
    restart_s : float, optional
        None (the paper): one expansion about t = 0 with ``H = t``. A step ``h``: the
        expansion restarts every ``h`` seconds (the series is summed at each boundary, which
        gives the next initial discretes, still affine in V) and ``H = t - t_k``; this is how
        the DT engine works and what keeps the round-off small for long times (a single
        expansion loses ``eps * e^(n t)`` to cancellation).

    Returns
    -------
    array ``(M, 2, 3, N)``
        Random spectra of x (component 0) and x' = g (component 1).
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    n_disc = int(n_discretes)
    if n_disc < 1:
        raise ValueError(f"n_discretes must be >= 1; found {n_disc}")
    n2 = float(n_rad_s) ** 2
    start = np.zeros((t.size, 2, 3))
    start[:, 0] = (x0_m, -1.0, 0.0)
    start[:, 1] = (g0_m_s, 0.0, -1.0)
    h = t.copy()
    if restart_s is not None:
        step = float(restart_s)
        if not step > 0:
            raise ValueError(f"restart_s must be > 0; found {restart_s}")
        k = np.floor(np.abs(t) / step)
        sign = np.sign(t)
        h = t - sign * k * step
        # the state at the boundaries, by summing one full step's spectra repeatedly
        one = _seed000_recurrence(np.eye(2)[None], np.array([step]), n2, n_disc).sum(-1)[0]   # (2, 2)
        back = _seed000_recurrence(np.eye(2)[None], np.array([-step]), n2, n_disc).sum(-1)[0]
        kmax = int(k.max(initial=0))
        powers_f, powers_b = [np.eye(2)], [np.eye(2)]
        for _ in range(kmax):
            powers_f.append(one @ powers_f[-1])
            powers_b.append(back @ powers_b[-1])
        trans = np.stack([(powers_f if s >= 0 else powers_b)[int(kk)] for s, kk in zip(sign, k)])
        start = np.einsum("mij,mjs->mis", trans, start)
    return _seed000_recurrence(start, h, n2, n_disc)


def _seed000_recurrence(start, h, n2, n_disc):
    """eq. 30 from initial discretes ``start (M, 2, S)`` at scales ``h (M,)``: (M, 2, S, N)."""
    out = np.zeros(start.shape + (n_disc,))
    out[..., 0] = start
    hh = np.asarray(h, float)[:, None]
    for k in range(n_disc - 1):
        out[:, 0, :, k + 1] = hh / (k + 1) * out[:, 1, :, k]
        out[:, 1, :, k + 1] = -n2 * hh / (k + 1) * out[:, 0, :, k]
    return out


def seed000_variance_exact(t_s, sigma1_m: float, sigma2_m_s: float, n_rad_s: float) -> np.ndarray:
    """Ground truth of seed 000's example: ``D_x(t) = s1^2 cos^2(n t) + s2^2 sin^2(n t) / n^2`` (m^2).

    The exact variance of ``x(t) = (x0 - v1) cos(n t) + (g0 - v2) sin(n t) / n`` for
    independent ``v1, v2`` (seed 000 item 3; docs/equations.md). The printed series (33)-(34) have
    coefficient typos and are not used.
    """
    nt = float(n_rad_s) * np.asarray(t_s, dtype=float)
    return sigma1_m ** 2 * np.cos(nt) ** 2 + (sigma2_m_s / n_rad_s) ** 2 * np.sin(nt) ** 2


def seed000_velocity_variance_exact(t_s, sigma1_m: float, sigma2_m_s: float, n_rad_s: float) -> np.ndarray:
    """``D_g(t) = s1^2 n^2 sin^2(n t) + s2^2 cos^2(n t)`` ((m/s)^2), the exact velocity variance."""
    nt = float(n_rad_s) * np.asarray(t_s, dtype=float)
    return (sigma1_m * n_rad_s) ** 2 * np.sin(nt) ** 2 + sigma2_m_s ** 2 * np.cos(nt) ** 2


def seed000_velocity_weight(t_s, n_rad_s: float) -> np.ndarray:
    """``(dD_x/d s2^2) / (dD_x/d s1^2) = tan^2(n t) / n^2`` (s^2): seed 000's conclusion.

    The paper argues (after eq. 34) that the coefficients of the velocity variance are orders
    of magnitude larger than those of the position variance for the same power of time. Per
    unit variance (m^2 against (m/s)^2) this weight exceeds 1 as soon as ``tan(n t) > n``
    (about 1 s) and grows monotonically up to a quarter period, where the position
    contribution vanishes.
    """
    nt = float(n_rad_s) * np.asarray(t_s, dtype=float)
    return np.tan(nt) ** 2 / n_rad_s ** 2


def seed000_enough_discretes(rho: float, tol: float = 1e-17) -> int:
    """Discretes N for which the series of ``cos``/``sin`` at ``|n H| <= rho`` is complete to ``tol``.

    The smallest N with ``rho^N / N! <= tol``: the first omitted discrete is below ``tol``
    times the state's scale, and the later ones fall faster still.
    """
    rho = abs(float(rho))
    n, term = 0, 1.0
    while term > tol:
        n += 1
        term *= rho / n
        if n > 100_000:
            raise ValueError(f"no practical number of discretes for n*H = {rho}")
    return max(n, 2)


def seed000_statistics(t_s, sigma1_m: float, sigma2_m_s: float, n_rad_s: float, *,
                       n_discretes: int | None = None, x0_m: float = 0.0, g0_m_s: float = 0.0) -> dict:
    """Mean, variance and standard deviation of position and velocity of seed 000's example.

    ``n_discretes`` = N: the paper's method, one expansion about t = 0 with ``H = t`` and N
    discretes (4 in eq. 33, 6 in eq. 34). None: "enough" discretes, the expansion restarted
    every ``0.5 / n`` seconds with N from :func:`seed000_enough_discretes` (about 1e-16
    relative per step).

    Returns a dict of arrays over ``t_s``: ``mean_x_m``, ``mean_vx_m_s``, ``var_x_m2``,
    ``var_vx_m2_s2``, ``sigma_x_m``, ``sigma_vx_m_s`` and the scalar ``n_discretes`` used.
    Implements seed 000 eqs. 18 and 25 on the spectra of eqs. 29-31.
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if n_discretes is None:
        restart = 0.5 / float(n_rad_s)
        n_disc = seed000_enough_discretes(0.5)
    else:
        restart, n_disc = None, int(n_discretes)
    spec = seed000_spectra(t, n_rad_s, n_disc, x0_m=x0_m, g0_m_s=g0_m_s, restart_s=restart)
    cov = np.diag([float(sigma1_m) ** 2, float(sigma2_m_s) ** 2])
    var = variance(spec, cov)                                     # (M, 2)
    mean = mean_spectrum(spec).sum(-1)                            # eq. 18 (H = t)
    return {"mean_x_m": mean[:, 0], "mean_vx_m_s": mean[:, 1], "var_x_m2": var[:, 0],
            "var_vx_m2_s2": var[:, 1], "sigma_x_m": np.sqrt(np.clip(var[:, 0], 0.0, None)),
            "sigma_vx_m_s": np.sqrt(np.clip(var[:, 1], 0.0, None)),
            "n_discretes": n_disc}


# =========================================================================== the DT engine's spectra

def _step_arrays(source):
    """(step index of each time fn, expansion times (S,), position spectra (S, 3, n),
    sensitivity spectra (S, 3, 6, n)) of a Taylor propagation, a propagator trajectory or its steps."""
    if hasattr(source, "step_times_s"):                       # taylor.Propagation
        if source.sensitivities is None:
            raise ValueError("the propagation carries no sensitivities; call propagate(..., stm=True)")
        if source.coefficients.shape[1] != 1:
            raise ValueError("state spectra need a single-trajectory propagation")
        tb = np.asarray(source.step_times_s, float)
        if tb.size < 2:
            raise ValueError("the propagation took no step")
        lo, hi = min(tb[0], tb[-1]), max(tb[0], tb[-1])
        forward = tb[-1] >= tb[0]

        def locate(t):
            slack = 8 * np.finfo(float).eps * max(abs(lo), abs(hi), 1.0)
            if t.size and (t.min() < lo - slack or t.max() > hi + slack):
                raise ValueError(f"times must lie in the propagated interval [{lo}, {hi}] s; "
                                 f"found [{t.min()}, {t.max()}]")
            idx = (np.searchsorted(tb, t, side="right") if forward
                   else np.searchsorted(-tb, -t, side="right")) - 1
            return np.clip(idx, 0, tb.size - 2)

        return locate, tb[:-1], source.coefficients[:, 0], source.sensitivities[:, 0, :, :6]
    steps = source.steps() if hasattr(source, "steps") else source   # propagator.Trajectory / Steps
    if steps.sensitivities is None:
        raise ValueError("the trajectory carries no sensitivities; propagate with stm=True")

    def locate_steps(t):
        return steps.locate(t)

    return locate_steps, steps.t_expand_s, steps.coefficients, steps.sensitivities


def state_spectra(propagation, t_s) -> np.ndarray:
    """First-order random spectra of the state at times ``t_s``, from a DT propagation.

    ``propagation``: a :class:`trackproc.dynamics.taylor.Propagation` of one trajectory made
    with ``stm=True``, or a :class:`trackproc.dynamics.propagator.Trajectory` (or its
    ``steps()``) made with ``stm=True`` -- then in its quasi-inertial frame, with derivatives
    with respect to the quasi-inertial initial state. For each time t, in the step expanded
    about ``t_s``, with ``H = t - t_s``: the position discretes ``X_H(K) = H^K X_1(K)`` and the
    velocity discretes by the derivative rule ``V_H(K) = (K+1)/H X_H(K+1) = (K+1) H^K X_1(K+1)``
    (docs/equations.md, notation), each with its derivatives with respect to the initial state (the
    engine's sensitivity spectra, seed 004 eqs. 19-21 to first order).

    Returns
    -------
    array ``(M, 6, 7, n)``
        Components ``x, y, z, vx, vy, vz``; slot 0 the nominal discretes, slots 1..6 their
        derivatives with respect to ``(x, y, z, vx, vy, vz)`` at the initial epoch (the
        random initial errors V); ``n = order + 2``. ``sum_K`` over the last axis gives the
        nominal state (slot 0) and the state transition matrix (slots 1..6).
    """
    locate, t_expand, coefs, senss = _step_arrays(propagation)
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    idx = locate(t)
    coef = coefs[idx]                                             # (M, 3, n)
    sens = senss[idx]                                             # (M, 3, 6, n)
    n = coef.shape[-1]
    pos = np.concatenate([coef[:, :, None, :], sens], axis=2)     # (M, 3, 7, n)
    vel = np.zeros_like(pos)
    vel[..., :n - 1] = sp.derivative(pos)                         # (K+1) X_1(K+1)
    spec = np.concatenate([pos, vel], axis=1)                     # (M, 6, 7, n)
    h = t - np.asarray(t_expand, float)[idx]
    hp = h[:, None] ** np.arange(n)                               # rescale to H = t - t_s
    return spec * hp[:, None, None, :]


def spectral_covariance(propagation, t_s, cov0, chunk: int = 512) -> np.ndarray:
    """Covariance ``P(t) = R(t, t)`` of the state at ``t_s`` by seed 000 eqs. 21-25: ``(M, 6, 6)``.

    ``cov0`` (6, 6): covariance of the initial state (same frame as the propagation). The
    random spectra are the first-order ones of :func:`state_spectra`; exact for a linear
    model, first order for two-body / J2. ``chunk`` bounds the memory (times per batch).
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    out = np.empty((t.size, 6, 6))
    lo = normalizing_factor(cov0)
    for a in range(0, t.size, chunk):
        spec = state_spectra(propagation, t[a:a + chunk])
        w = np.einsum("mcjn,jk->mckn", spec[:, :, 1:], lo)        # normalised random part
        out[a:a + chunk] = _cross_sum(w, w)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def _cross_sum(w1, w2):
    """``sum_K sum_j (W1_aj * W2_bj)(K)`` for paired times: (M, A, B)."""
    n1, n2 = w1.shape[-1], w2.shape[-1]
    r = np.zeros(w1.shape[:-3] + (w1.shape[-3], w2.shape[-3], n1 + n2 - 1))
    for l in range(n1):
        r[..., l:l + n2] += np.einsum("...aj,...bjn->...abn", w1[..., l], w2)
    return r.sum(-1)


def spectral_cross_covariance(propagation, t1_s, t2_s, cov0) -> np.ndarray:
    """``R(t1_i, t2_j) = sum_K R(K, t1_i, t2_j)`` for all pairs (seed 000 eqs. 21-25).

    Returns ``(M1, M2, 6, 6)``: ``E[dx(t1_i) dx(t2_j)^T]`` of the state errors. The diagonal
    blocks at ``t1 = t2`` are :func:`spectral_covariance`.
    """
    s1 = state_spectra(propagation, t1_s)
    s2 = state_spectra(propagation, t2_s)
    lo = normalizing_factor(cov0)
    w1 = np.einsum("mcjn,jk->mckn", s1[:, :, 1:], lo)
    w2 = np.einsum("mcjn,jk->mckn", s2[:, :, 1:], lo)
    out = np.empty((w1.shape[0], w2.shape[0], 6, 6))
    for i in range(w1.shape[0]):
        out[i] = _cross_sum(np.broadcast_to(w1[i], w2.shape[:1] + w1.shape[1:]), w2)
    return out


def spectral_factors(propagation, t_s, cov0) -> np.ndarray:
    """``F(t) = sum_K W(K, t)``, the summed normalised random discretes ``dX(K)/dV L``: ``(M, 6, k)``.

    The sum over K of a complete Cauchy product is the product of the two sums, so eq. 25
    factorises exactly: ``R(t1, t2) = F(t1) F(t2)^T`` -- the same numbers as
    :func:`spectral_cross_covariance` (tested) at the cost of one product per pair of times
    instead of a Cauchy product, for correlation matrices over long time grids.
    """
    spec = state_spectra(propagation, t_s)
    lo = normalizing_factor(cov0)
    return np.einsum("mcjn,jk->mck", spec[:, :, 1:], lo)


# =========================================================================== STM and Monte Carlo

def stm_covariance(phi, cov0) -> np.ndarray:
    """Linear covariance propagation ``P(t) = Phi(t) P0 Phi(t)^T``: ``phi (..., 6, 6)`` -> ``(..., 6, 6)``."""
    phi = np.asarray(phi, dtype=float)
    p = np.einsum("...ij,jk,...lk->...il", phi, np.asarray(cov0, float), phi)
    return 0.5 * (p + np.swapaxes(p, -1, -2))


def stm_cross_covariance(phi1, phi2, cov0) -> np.ndarray:
    """``R(t1_i, t2_j) = Phi(t1_i) P0 Phi(t2_j)^T``: ``(M1, 6, 6), (M2, 6, 6)`` -> ``(M1, M2, 6, 6)``."""
    return np.einsum("aij,jk,blk->abil", np.asarray(phi1, float), np.asarray(cov0, float),
                     np.asarray(phi2, float))


def sample_initial_states(state0, cov0, n_samples: int, seed: int | None = None) -> np.ndarray:
    """``n_samples`` draws of ``N(state0, cov0)``: ``state0 + L xi``, ``xi ~ N(0, I)`` (``(N, 6)``).

    ``L`` from :func:`normalizing_factor` (a semi-definite covariance is fine);
    ``numpy.random.default_rng(seed)``: the same seed gives the same draws.
    """
    n = int(n_samples)
    if n < 2:
        raise ValueError(f"Monte Carlo needs at least 2 samples; found {n}")
    x0 = np.asarray(state0, dtype=float).reshape(-1)
    lo = normalizing_factor(cov0)
    xi = np.random.default_rng(seed).standard_normal((n, lo.shape[1]))
    return x0[None, :] + xi @ lo.T


def sample_covariance(samples) -> tuple[np.ndarray, np.ndarray]:
    """Sample mean and covariance (divisor N - 1) over the first axis of ``samples (N, ..., k)``.

    Returns ``(mean (..., k), cov (..., k, k))``.
    """
    x = np.asarray(samples, dtype=float)
    n = x.shape[0]
    mean = x.mean(axis=0)
    d = x - mean
    cov = np.einsum("n...i,n...j->...ij", d, d) / (n - 1)
    return mean, cov


def monte_carlo_bounds(n_samples: int) -> dict:
    """Statistical spread of Monte Carlo second moments from N Gaussian draws.

    * sample variance ``s^2`` of a Gaussian component: ``sd(s^2) / sigma^2 = sqrt(2/(N-1))``;
    * sample standard deviation: ``sd(s) / sigma ~ 1/sqrt(2(N-1))`` (first order);
    * sample covariance: ``sd(s_ij) = sqrt((sigma_i^2 sigma_j^2 + sigma_ij^2) / (N-1))``
      (use :func:`covariance_sd`).

    Exact for linear propagation of Gaussian errors (the propagated state is then Gaussian);
    for the nonlinear motion it is the spread around the Monte Carlo's own limit.
    """
    n = int(n_samples)
    if n < 2:
        raise ValueError(f"Monte Carlo needs at least 2 samples; found {n}")
    return {"n_samples": n, "variance_relative_sd": math.sqrt(2.0 / (n - 1)),
            "sigma_relative_sd": 1.0 / math.sqrt(2.0 * (n - 1))}


def covariance_sd(cov, n_samples: int) -> np.ndarray:
    """Standard deviation of each element of a sample covariance of N Gaussian draws."""
    c = np.asarray(cov, dtype=float)
    d = np.diagonal(c, axis1=-2, axis2=-1)
    return np.sqrt((d[..., :, None] * d[..., None, :] + c * c) / (int(n_samples) - 1))


# =========================================================================== frames, stations, output

def range_range_rate_jacobian(r, v, r_st, v_st) -> np.ndarray:
    """Partials of range and range-rate with respect to the satellite state: ``(..., 2, 6)``.

    Geometric (instantaneous) range ``rho = |r - r_st|`` and range-rate
    ``rho' = u . (v - v_st)``, ``u = (r - r_st)/rho`` (seed 002 eq. 17 with the station's
    motion): ``d rho/d r = u``, ``d rho'/d r = (dv - u (u . dv)) / rho``, ``d rho'/d v = u``.
    The light time changes these partials by ``v/c`` (~3e-5 relative), below the statistics'
    own accuracy. The partials are :func:`trackproc.models.observables.range_partials` and
    :func:`~trackproc.models.observables.range_rate_partials` (``instantaneous``) at ``r, v``.
    """
    from trackproc.models.observables import range_partials, range_rate_partials

    _, _, d_rho = range_partials(r, r_st)
    _, d_rr_r, d_rr_v = range_rate_partials(r, v, r_st, v_st, "instantaneous")
    out = np.zeros(d_rho.shape[:-1] + (2, 6))
    out[..., 0, :3] = d_rho
    out[..., 1, :3] = d_rr_r
    out[..., 1, 3:] = d_rr_v
    return out


def observable_covariance(jac, cov) -> np.ndarray:
    """``J P J^T`` for ``jac (..., k, 6)`` and ``cov (..., 6, 6)``: ``(..., k, k)``."""
    return np.einsum("...ij,...jk,...lk->...il", np.asarray(jac, float), np.asarray(cov, float),
                     np.asarray(jac, float))


def sigmas(cov) -> np.ndarray:
    """Standard deviations ``sqrt(diag)`` of covariances ``(..., k, k)`` (negative round-off -> 0)."""
    return np.sqrt(np.clip(np.diagonal(np.asarray(cov, float), axis1=-2, axis2=-1), 0.0, None))


def correlation_coefficients(cross, var1, var2) -> np.ndarray:
    """``R(t1, t2) / sqrt(D(t1) D(t2))`` with 0 where a variance vanishes."""
    den = np.sqrt(np.multiply.outer(np.asarray(var1, float), np.asarray(var2, float)))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, np.asarray(cross, float) / np.where(den > 0, den, 1.0), 0.0)
