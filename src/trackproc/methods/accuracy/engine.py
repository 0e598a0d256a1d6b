"""The Taylor (DT) engine's sensitivity spectra as random spectra of the state, and the spectral covariance (method 1).
"""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import spectra as sp

from trackproc.methods.accuracy.moments import normalizing_factor


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
