"""Dense output of the Taylor (DT) engine: every step's position spectra, evaluated at any times.

A :class:`Propagation` keeps, for each step, the spectrum of the position (and of its
sensitivities); the state at any set of times is the inverse transform (one matrix product per
step: powers of the offsets x coefficients), without re-integration, and velocity and higher
derivatives are derivatives of the same series (seed 004 eq. 13, the inverse transform).
:func:`trackproc.dynamics.taylor.propagate` builds it; the propagator façade and the full-force
integrator (:mod:`trackproc.dynamics.forces.integrator`) return it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from functools import lru_cache

import numpy as np

from trackproc.errors import ProcessingError

__all__ = ["Outcome", "Propagation"]


class Outcome(Enum):
    """How a propagation ended."""

    SUCCESS = "success"          #: the requested end time was reached
    STEP_LIMIT = "step_limit"    #: ``max_steps`` steps were taken before the end time
    NON_FINITE = "non_finite"    #: a coefficient became NaN or infinite (e.g. r = 0)
    REENTRY = "reentry"          #: the orbit came below the re-entry radius (full force model)



_EPS = float(np.finfo(float).eps)


def _powers(dt, n):
    """Powers ``dt^k``, k = 0..n-1, shape (n, M), by doubling (log2 n vector products)."""
    p = np.empty((n, dt.size))
    p[0] = 1.0
    if n > 1:
        p[1] = dt
    k = 2
    while k < n:
        j = min(k, n - k)
        np.multiply(p[:j], p[k - 1] * dt, out=p[k:k + j])
        k += j
    return p


@lru_cache(maxsize=64)
def _deriv_factors(n, m):
    """(2, max(n-m,1)): K!/(K-d)! for K = d..n-1 at power K-d, d = m and m+1."""
    nm = max(n - m, 1)
    out = np.zeros((2, nm))
    for i, d in enumerate((m, m + 1)):
        for j in range(max(n - d, 0)):
            out[i, j] = math.perm(j + d, d)
    return out


@dataclass(frozen=True, eq=False)
class Propagation:
    """Result of :func:`propagate`: the outcome and every step's spectra (dense output).

    Attributes
    ----------
    outcome : Outcome
    step_times_s : array ``(n_steps + 1,)``
        Step boundaries, s (decreasing for a backward propagation); ``step_times_s[-1]`` is the
        time reached.
    coefficients : array ``(n_steps, B, 3, p + 2)``
        Position spectra of each step with H = 1 s around the step's start (the velocity is
        their derivative). B = 1 for a single trajectory.
    sensitivities : array ``(n_steps, B, 3, P, p + 2)`` or None
        Spectra of d position / d parameter, parameters named in ``parameters``.
    order, tol, force, mu_m3_s2, j2, re_m : the settings used.
    batch : bool
        True when the initial state had a leading batch axis (outputs keep it).
    engine : ``"numpy"`` or ``"compiled"``
        Which step loop made it (:mod:`trackproc.dynamics.taylor_jit` for ``"compiled"``); a
        compiled propagation also evaluates its dense output with the compiled kernel.

    Evaluation (dense output, no re-integration): :meth:`state` (and its time derivatives),
    :meth:`stm`, :meth:`jacobian`, :meth:`dstate_dmu` at any times inside the interval covered.

    Examples
    --------
    A circular orbit of radius 7000 km comes back after one period:

    >>> import numpy as np
    >>> from trackproc.constants import MU_EARTH
    >>> v = np.sqrt(MU_EARTH / 7.0e6); period = 2 * np.pi * 7.0e6 / v
    >>> res = propagate([7.0e6, 0, 0, 0, v, 0], 0.0, period, force="two-body")
    >>> res.outcome.value, res.n_steps
    ('success', 4)
    >>> bool(np.abs(res.state(period)[:3] - [7.0e6, 0, 0]).max() < 1e-6)
    True
    >>> res.state(np.linspace(0.0, 600.0, 601)).shape
    (601, 6)
    """

    outcome: Outcome
    step_times_s: np.ndarray
    coefficients: np.ndarray
    sensitivities: np.ndarray | None
    parameters: tuple
    order: int
    tol: float
    force: str
    mu_m3_s2: float
    j2: float
    re_m: float
    batch: bool
    engine: str = "numpy"
    #: derivative spectra of a step, made once: (values or sensitivities, step, m) -> (B*2F, n-m);
    #: and the interval covered with its slack ("bounds")
    _spectra: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    #: the last times evaluated and their plan (:meth:`_plan`): a light-time solution reads the
    #: state, its derivative and the STM at the same emission times
    _last: list = field(default_factory=list, init=False, repr=False, compare=False)

    # -- summary -----------------------------------------------------------------------------
    @property
    def n_steps(self) -> int:
        return self.coefficients.shape[0]

    @property
    def step_sizes_s(self) -> np.ndarray:
        return np.diff(self.step_times_s)

    @property
    def t0_s(self) -> float:
        return float(self.step_times_s[0])

    @property
    def t_end_s(self) -> float:
        return float(self.step_times_s[-1])

    def raise_for_outcome(self) -> "Propagation":
        """Raise :class:`ProcessingError` unless the end time was reached; return self."""
        if self.outcome is not Outcome.SUCCESS:
            raise ProcessingError(
                f"Taylor propagation stopped ({self.outcome.value}) at t = {self.t_end_s} s "
                f"after {self.n_steps} steps",
                {"outcome": self.outcome.value, "t_reached_s": self.t_end_s,
                 "steps": self.n_steps})
        return self

    # -- dense output ------------------------------------------------------------------------
    def covers(self, t) -> bool:
        """Whether every time of the 1-D ``t`` lies in the interval :meth:`_locate` accepts."""
        lo, hi, slack = self._bounds()
        return (not t.size) or bool(lo - slack <= t.min() and t.max() <= hi + slack)

    def keep_plan(self, tf, idx, groups) -> None:
        """Keep ``(idx, groups)`` as :meth:`_plan`'s answer for the 1-D times ``tf`` (a caller that
        computed the powers of several runs' times at once)."""
        self._last[:] = [(tf.tobytes(), idx, groups)]

    def _bounds(self):
        bounds = self._spectra.get("bounds")
        if bounds is None:
            tb = self.step_times_s
            lo, hi = (tb[0], tb[-1]) if tb[-1] >= tb[0] else (tb[-1], tb[0])
            bounds = self._spectra["bounds"] = (lo, hi, 8 * _EPS * max(abs(lo), abs(hi), 1.0))
        return bounds

    def _locate(self, t):
        """Step index of every time in ``t`` (1-D); ValueError outside the interval."""
        tb = self.step_times_s
        if self.n_steps == 0:
            raise ValueError("no step was taken; nothing to evaluate")
        lo, hi, slack = self._bounds()
        tmin, tmax = (t.min(), t.max()) if t.size else (lo, hi)
        if not (lo - slack <= tmin and tmax <= hi + slack):
            raise ValueError(f"times must lie in the propagated interval [{lo}, {hi}] s; "
                             f"found [{tmin}, {tmax}]")
        if self.n_steps == 1:
            return None
        if tb[-1] >= tb[0]:
            idx = np.searchsorted(tb, t, side="right") - 1
        else:
            idx = np.searchsorted(-tb, -t, side="right") - 1
        return np.clip(idx, 0, self.n_steps - 1)

    def _derivative_spectra(self, coef, s, m, key):
        """Spectra of derivatives m and m+1 of step s of coef, (B*2F, max(n-m, 1)); kept, since
        a light-time iteration evaluates the same steps several times."""
        cd = self._spectra.get((key, s, m))
        if cd is None:
            _, nb, nf, n = coef.shape
            nm = max(n - m, 1)
            fac = _deriv_factors(n, m)                                # (2, nm)
            cs = coef[s]                                              # (B, F, n)
            cd = np.zeros((nb, 2, nf, nm))
            if m < n:
                cd[:, 0, :, :n - m] = cs[..., m:] * fac[0, :n - m]
            if m + 1 < n:
                cd[:, 1, :, :n - m - 1] = cs[..., m + 1:] * fac[1, :n - m - 1]
            cd = self._spectra[(key, s, m)] = cd.reshape(nb * 2 * nf, nm)
        return cd

    def _plan(self, tf):
        """Step index (None for one step) of the 1-D times ``tf`` and their groups ``[step,
        selection, offsets, powers]`` (filled by :meth:`_dense`), kept for the last times asked:
        the state, its derivative and the STM read at the same times share one location and one
        set of powers.

        The powers are those of the longest series asked so far: ``_powers(dt, k)`` is the first
        ``k`` rows of ``_powers(dt, n)`` for ``k <= n`` (the doubling computes every row by the
        same product whatever ``n``), so a shorter series takes a prefix of the same numbers."""
        key = tf.tobytes()
        entry = self._last[0] if self._last else None             # one read: (key, idx, groups)
        if entry is not None and entry[0] == key:
            return entry[1], entry[2]
        idx = self._locate(tf)
        groups = []
        self._last[:] = [(key, idx, groups)]
        return idx, groups

    @staticmethod
    def _groups(idx):
        """``[step, selection]`` of the times of each step touched (slices when sorted)."""
        if idx is None:
            return [[0, None]]
        if (idx[1:] >= idx[:-1]).all():                              # sorted: slices
            cuts = np.flatnonzero(np.diff(idx)) + 1
            starts = np.concatenate([[0], cuts])
            ends = np.concatenate([cuts, [idx.size]])
            return [[int(idx[a]), slice(int(a), int(b))] for a, b in zip(starts, ends)]
        order = np.argsort(idx, kind="stable")
        sidx = idx[order]
        cuts = np.flatnonzero(np.diff(sidx)) + 1
        return [[int(idx[g[0]]), g] for g in np.split(order, cuts)]

    def _dense(self, coef, t_s, m, key="state"):
        """Derivatives m and m+1 of spectra coef (n_steps, B, F, n) at t_s.

        Returns (B, M, 2, F) and the shape of t_s. One matrix product per step touched:
        powers of the offsets (M, n) x derivative spectra (n, 2F). ``key`` names coef
        (``"state"`` or ``"jacobian"``) for the kept derivative spectra.
        """
        t = np.asarray(t_s, dtype=float)
        tf = t.reshape(-1)
        _, nb, nf, n = coef.shape
        if tf.size == 0:
            return np.empty((nb, 0, 2, nf)), t.shape
        rows = self._dense_rows(coef, tf, m, key)
        if rows is None:
            from trackproc.dynamics import jit, taylor_jit  # start-up: numba, loaded only for the compiled engine

            with jit.compile_once([taylor_jit.dense], "taylor-dense", "the Taylor engine's kernels", 6):
                return taylor_jit.dense(np.ascontiguousarray(coef), np.ascontiguousarray(self.step_times_s,
                                                                                         dtype=float),
                                        self._plan(tf)[0].astype(np.int64), np.ascontiguousarray(tf), m), t.shape
        out = rows.transpose(0, 3, 1, 2)
        if rows.base is None:
            out = np.ascontiguousarray(out)      # several steps filled it: the layout callers had
        return out, t.shape

    def _dense_rows(self, coef, tf, m, key):
        """Derivatives m and m+1 of spectra coef at the 1-D times ``tf`` as the products give them,
        (B, 2, F, M), the times last; None where the compiled kernel evaluates instead (many
        steps, few samples a step: :meth:`_dense`)."""
        idx, groups = self._plan(tf)
        _, nb, nf, n = coef.shape
        nm = max(n - m, 1)
        # compiled (numba is loaded already) when steps are many and samples per step few; one
        # BLAS product per step wins for hundreds of samples in a step (a pass: 601 in 1 step)
        if self.engine == "compiled" and idx is not None and tf.size <= 64 * self.n_steps:
            return None
        if not groups:
            groups.extend(g + [None, None] for g in self._groups(idx))
        out = None if len(groups) == 1 else np.empty((nb, 2, nf, tf.size))
        tb = self.step_times_s
        for group in groups:
            s, sel, dt, pw = group
            if pw is None or pw.shape[0] < nm:
                if dt is None:
                    dt = group[2] = (tf if sel is None else tf[sel]) - tb[s]
                pw = group[3] = _powers(dt, nm)
            # one 2-D product of contiguous operands (BLAS), (B*2F, nm) @ (nm, M)
            res = (self._derivative_spectra(coef, s, m, key) @ pw[:nm]).reshape(nb, 2, nf, -1)
            if out is None:
                out = res
            else:
                out[..., sel] = res
        return out

    def stm_rows(self, t_s):
        """``Phi`` at the 1-D times ``t_s`` as (6, 6, M), ``[row, column, time]`` (the layout of the
        products: a rotation of every matrix is then two matrix products, without transposing
        them first), or None where :meth:`stm` has to be used (batch mode, compiled kernel)."""
        if self.sensitivities is None or self.batch:
            return None
        sens = self.sensitivities
        nsteps, nb, _, npar, n = sens.shape
        tf = np.asarray(t_s, dtype=float).reshape(-1)
        if nb != 1 or tf.size == 0:
            return None
        rows = self._dense_rows(sens.reshape(nsteps, nb, 3 * npar, n), tf, 0, "jacobian")
        if rows is None:
            return None
        rows = rows.reshape(6, npar, tf.size)
        return rows if npar == 6 else rows[:, :6]

    def _finish(self, arr, tshape, tail):
        """(B, M, ...) -> (B?,) + tshape + tail."""
        shape = tshape + tail
        if self.batch:
            return arr.reshape((arr.shape[0],) + shape)
        return arr.reshape(shape)

    def state(self, t_s, derivative: int = 0) -> np.ndarray:
        """State ``[r, v]`` (m, m/s) at times ``t_s``, or its ``derivative``-th time derivative.

        Shape ``t_s.shape + (6,)``, with a leading batch axis in batch mode. ``derivative=1``
        gives ``[v, a]``, and so on (derivatives of the step's series, exact to the tolerance).
        Times must lie inside the propagated interval.
        """
        m = int(derivative)
        if m < 0:
            raise ValueError(f"derivative must be >= 0; found {m}")
        out, tshape = self._dense(self.coefficients, t_s, m)
        return self._finish(out, tshape, (6,))

    def jacobian(self, t_s) -> np.ndarray:
        """d state(t) / d parameters, shape ``t_s.shape + (6, P)`` (parameters in ``.parameters``)."""
        if self.sensitivities is None:
            raise ValueError("this propagation carries no sensitivities; "
                             "call propagate(..., stm=True)")
        sens = self.sensitivities
        nsteps, nb, _, npar, n = sens.shape
        coef = sens.reshape(nsteps, nb, 3 * npar, n)
        out, tshape = self._dense(coef, t_s, 0, "jacobian")
        out = out.reshape(out.shape[:2] + (6, npar))
        return self._finish(out, tshape, (6, npar))

    def stm(self, t_s) -> np.ndarray:
        """State transition matrix ``Phi(t, t0) = d state(t) / d state(t0)``, ``(..., 6, 6)``."""
        return self.jacobian(t_s)[..., :6]

    def dstate_dmu(self, t_s) -> np.ndarray:
        """d state(t) / d mu (state units per m^3/s^2), ``(..., 6)``; needs ``mu_sensitivity``."""
        if "mu" not in self.parameters:
            raise ValueError("this propagation has no mu sensitivity; "
                             "call propagate(..., stm=True, mu_sensitivity=True)")
        return self.jacobian(t_s)[..., self.parameters.index("mu")]
