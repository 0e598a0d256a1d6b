"""The seed 000 worked example (eqs. 29-34): its spectra, the exact variances and the truncation statistics.
"""

from __future__ import annotations

import numpy as np

from trackproc.methods.accuracy.moments import mean_spectrum, variance


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
