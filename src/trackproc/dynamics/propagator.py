"""Propagation façade: a GCRF state at a UTC epoch in, GCRF states, STM and covariance out.

The Taylor (DT) engine (:mod:`trackproc.dynamics.taylor`) integrates in a frame whose z axis
is the Earth's rotation axis, with plain float seconds. This module does the bookkeeping
around it, once, for every command that propagates:

1. **Frame.** The state is rotated from GCRF into the
   :class:`~trackproc.dynamics.frames.QuasiInertialFrame` of a reference epoch (GCRF rotated by
   that epoch's bias-precession-nutation matrix ``q``; by default the state's own epoch, as
   :func:`trackproc.pipeline.simulate.simulate` does), so J2 acts about the rotation axis of
   that epoch (README "Units, sign conventions, time and frames"). Results are rotated back to GCRF: states by
   ``blockdiag(q, q)^T``, the STM as ``Q^T Phi Q`` with ``Q = blockdiag(q, q)``.
2. **Time.** ``t_s`` are SI seconds from the state's epoch (through TAI, so leap seconds
   count), or UTC ``datetime64`` labels wherever times are taken;
   :meth:`Trajectory.seconds` converts labels to seconds and :meth:`Trajectory.times_utc`
   back.
3. **Direction.** Times before the epoch are covered by a backward run, times after it by a
   forward run, both starting from the epoch state (so the STM is the identity at t = 0).
4. **Outcome.** A run that stops early (step limit, non-finite state) is kept with its
   outcome; :meth:`Trajectory.raise_for_outcome` turns it into a
   :class:`~trackproc.errors.ProcessingError` (exit code 1 at the command line).

Example (the seed 004 orbit, one hour, J2, with the STM):

>>> import numpy as np
>>> from trackproc.dynamics.propagator import propagate
>>> traj = propagate([3774841.0, -1538034.0, 5924146.0], [-4816.6, 3936.4, 4091.1],
...                  np.datetime64("2026-03-20T09:30:00"), [-600.0, 3600.0], stm=True)
>>> traj.state(np.array([0.0, 3600.0])).shape, traj.stm(1800.0).shape
((2, 6), (6, 6))
>>> bool(np.allclose(traj.stm(0.0), np.eye(6)))
True

Everything here is pure numpy on SI units; nothing reads files or prints.

One responsibility, the one door to the numerical engines (the Taylor series for two-body and J2,
DOP853 for the full force model) and the trajectory they return; ~610 lines, most of it the
trajectory's interpolation and that door's argument checks and docs, the same door for a run
restarted from a later state (:func:`propagate_from`, read on the first epoch's time axis), and the
trajectory's kept reads (the last times' split and powers, which the light time reads three times:
state, derivative, STM). The kept reads could move to a module of their own with the interpolation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.dynamics import taylor, taylor_dense, timescales as ts
from trackproc.dynamics.frames import QuasiInertialFrame, earth_rotation
from trackproc.dynamics.gravity import force_parameters  # noqa: F401  (re-exported: propagator.force_parameters)
from trackproc import vocabulary
from trackproc.errors import ProcessingError
from trackproc.isotime import iso_utc

__all__ = ["FORCES", "Trajectory", "Steps", "propagate", "propagate_state", "force_parameters", "reference_frame"]

FORCES = vocabulary.FORCES
#: Length of the run made when every requested time is the epoch itself (s).
_MIN_SPAN_S = 1.0


@dataclass(frozen=True)
class Steps:
    """Every Taylor step of a trajectory in time order, in the quasi-inertial frame.

    ``t_lo_s``, ``t_hi_s`` (S,): the interval a step covers; ``t_expand_s`` (S,): the time its
    spectra are expanded about (the step's start: ``t_lo_s`` forward, ``t_hi_s`` backward);
    ``coefficients`` (S, 3, n): position spectra, H = 1 s; ``sensitivities`` (S, 3, 6, n) or
    None: spectra of d position / d (initial quasi-inertial state).
    """

    t_lo_s: np.ndarray
    t_hi_s: np.ndarray
    t_expand_s: np.ndarray
    coefficients: np.ndarray
    sensitivities: np.ndarray | None

    def locate(self, t_s) -> np.ndarray:
        """Index of the step covering each time (the nearest step for times just outside)."""
        idx = np.searchsorted(self.t_lo_s, np.asarray(t_s, float), side="right") - 1
        return np.clip(idx, 0, self.t_lo_s.size - 1)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A propagated orbit: evaluate GCRF states, the STM and covariances at any covered time.

    Attributes
    ----------
    epoch : datetime64[ns]
        UTC epoch of the initial state (``t_s = 0``).
    epoch_jd_utc : tuple
        The same as a two-part UTC Julian date.
    frame : QuasiInertialFrame
        The integration frame (its ``q`` is GCRF -> quasi-inertial).
    runs : tuple of :class:`~trackproc.dynamics.taylor.Propagation`
        The backward run (if any) then the forward run (if any), both from ``t_s = 0``.
    force, mu_m3_s2, j2, re_m, tol : the model and tolerance used.
    t_min_s, t_max_s : float
        The requested interval (seconds from the epoch) the runs were asked to cover.
    initial_gcrf : (6,)
        The epoch state as given: :meth:`state` returns it unrotated at ``t_s = 0``.
    """

    epoch: np.datetime64
    epoch_jd_utc: tuple
    frame: QuasiInertialFrame
    runs: tuple
    force: str
    mu_m3_s2: float
    j2: float
    re_m: float
    tol: float
    t_min_s: float
    t_max_s: float
    initial_gcrf: np.ndarray | None = None
    force_model: object = None          # the ForceModel of force "full" (its describe() for metadata)

    # -- summary -----------------------------------------------------------------------------
    @property
    def has_stm(self) -> bool:
        return all(run.sensitivities is not None for run in self.runs)

    @property
    def outcome(self) -> taylor.Outcome:
        """SUCCESS when every run reached its end time, else the first failure."""
        for run in self.runs:
            if run.outcome is not taylor.Outcome.SUCCESS:
                return run.outcome
        return taylor.Outcome.SUCCESS

    @property
    def order(self) -> int:
        return self.runs[0].order

    @property
    def n_steps(self) -> int:
        return sum(run.n_steps for run in self.runs)

    @property
    def rotation(self) -> np.ndarray:
        """``blockdiag(q, q)`` (6, 6): GCRF state -> quasi-inertial state."""
        big = self.__dict__.get("_rotation")
        if big is None:
            big = np.zeros((6, 6))
            big[:3, :3] = big[3:, 3:] = self.frame.q
            self.__dict__["_rotation"] = big
        return big.copy()

    def raise_for_outcome(self) -> Trajectory:
        """Raise :class:`ProcessingError` unless every run reached its end; return self."""
        for run in self.runs:
            if run.outcome is taylor.Outcome.REENTRY:
                from trackproc.dynamics.forces.integrator import REENTRY_RADIUS_M  # start-up: as in propagate

                reached = self.times_utc(run.t_end_s)
                raise ProcessingError(
                    f"the orbit re-enters: its geocentric radius fell below {REENTRY_RADIUS_M / 1e3:g} km (about "
                    f"100 km altitude) at {iso_utc(reached, 3)} (t = {run.t_end_s:.3f} s from the epoch); "
                    "propagation stopped there",
                    {"outcome": run.outcome.value, "t_reached_s": run.t_end_s, "steps": run.n_steps})
            if run.outcome is not taylor.Outcome.SUCCESS:
                reached = self.times_utc(run.t_end_s)
                raise ProcessingError(
                    f"propagation stopped ({run.outcome.value}) at {iso_utc(reached, 3)} "
                    f"(t = {run.t_end_s:.3f} s from the epoch) after {run.n_steps} steps",
                    {"outcome": run.outcome.value, "t_reached_s": run.t_end_s, "steps": run.n_steps})
        return self

    # -- time --------------------------------------------------------------------------------
    def seconds(self, times_utc) -> np.ndarray:
        """SI seconds from the epoch of UTC ``datetime64`` labels (leap seconds counted)."""
        jd1, jd2 = ts.datetime64_to_jd_utc(np.asarray(times_utc, dtype="datetime64[ns]"))
        return np.asarray(ts.seconds_since((jd1, jd2), self.epoch_jd_utc), float)

    def times_utc(self, t_s) -> np.ndarray:
        """UTC ``datetime64[ns]`` of times ``t_s`` (s from the epoch)."""
        jd1, jd2 = ts.add_seconds_utc(self.epoch_jd_utc, np.asarray(t_s, float))
        return ts.jd_utc_to_datetime64(jd1, jd2)

    # -- evaluation --------------------------------------------------------------------------
    def _as_seconds(self, t_s) -> np.ndarray:
        """Seconds from the epoch; UTC ``datetime64`` values are converted."""
        if type(t_s) is np.ndarray and t_s.dtype == np.float64:
            return t_s
        t = np.asarray(t_s)
        if np.issubdtype(t.dtype, np.datetime64):
            return self.seconds(t)
        return np.asarray(t, float)

    def _layout(self):
        """``([(run, backward)], only backward, complete)``: the runs and their directions, made
        once; ``complete`` when a backward and a forward run both have steps (every time is then
        covered by one of them)."""
        layout = self.__dict__.get("_run_layout")
        if layout is None:
            runs = [(run, run.t_end_s < run.t0_s) for run in self.runs]
            only_back = not any(run.t_end_s > run.t0_s for run in self.runs)
            complete = (any(b and run.n_steps for run, b in runs)
                        and any(not b and run.n_steps for run, b in runs))
            layout = self.__dict__["_run_layout"] = (runs, only_back, complete)
        return layout

    def _split(self, t_s):
        """``(shape, flat times, [(run, selection, its times)], where the epoch is or None)``, kept
        for the last times asked (the light time reads the state, its derivative and the STM at
        the same emission times)."""
        t = self._as_seconds(t_s)
        key = (t.shape, t.tobytes())
        last = self.__dict__.get("_last_split")
        if last is not None and last[0] == key:
            return last[1]
        runs, only_back, complete = self._layout()
        flat = t.reshape(-1).copy()              # kept: the caller may change its array later
        back = flat < 0.0
        if only_back:
            back |= flat == 0.0                  # only a backward run: it starts at t = 0
        n_back = np.count_nonzero(back)
        # the backward times first (samples in time order): slices, not selections
        prefix = np.count_nonzero(back[:n_back]) == n_back
        parts = []
        for run, backward in runs:
            if not run.n_steps or n_back == (0 if backward else flat.size):
                continue
            if prefix:
                sel = slice(0, n_back) if backward else slice(n_back, None)
            else:
                sel = back if backward else ~back
            parts.append((run, sel, flat[sel]))
        if not complete:
            covered = np.zeros(flat.size, bool)
            for _, sel, _ in parts:
                covered[sel] = True
            if not covered.all():
                bad = flat[~covered]
                raise ValueError(f"times {bad.min()} .. {bad.max()} s lie outside the propagated interval "
                                 f"[{self.t_min_s}, {self.t_max_s}] s")
        zero = flat == 0.0
        split = (t.shape, flat, parts, zero.reshape(t.shape) if zero.any() else None)
        self.__dict__["_last_split"] = (key, split)
        if len(parts) > 1:
            self._share_powers(flat, parts, key[1])
        return split

    def _share_powers(self, flat, parts, flat_bytes: bytes) -> None:
        """Give runs of one step each, all expanded about the same time (the epoch: both runs start
        there), the powers of their offsets as columns of one set computed for all the times:
        each column is the same products whichever run's times it sits with (each run's kept
        plan, :meth:`taylor_dense.Propagation._plan`, then finds them).

        The powers depend on the times alone: the last set is kept for the next trajectory (a
        light-time solution starts where the previous model evaluation's ended, at the same
        emission times), read-only."""
        runs = tuple(run for run, _, _ in parts)
        kept = self.__dict__.get("_shared_powers")
        if kept is None or kept[0] != runs:
            # whether the runs qualify, their common start and the longest series: fixed for the runs
            kept = self.__dict__["_shared_powers"] = (runs, self._shared_series(runs))
        if kept[1] is None:
            return
        t0, n = kept[1]
        for run, _, times in parts:
            if not run.covers(times):
                return                          # let the run's own evaluation raise its error
        memo_key = (float(t0), n, flat_bytes)
        last = _LAST_POWERS[0]                  # one read: (key, offsets, powers)
        if last is not None and last[0] == memo_key:
            dt, pw = last[1], last[2]
        else:
            dt = flat - t0
            pw = taylor_dense._powers(dt, n)
            dt.flags.writeable = pw.flags.writeable = False     # shared: the runs' plans hold views
            _LAST_POWERS[0] = (memo_key, dt, pw)
        for run, sel, times in parts:
            run.keep_plan(times, None, [[0, None, dt[sel], pw[:, sel]]])

    @staticmethod
    def _shared_series(runs):
        """``(start, series length)`` of :meth:`_share_powers` for ``runs``, or None where they do not
        share one expansion (more than one step, batch, different starts)."""
        if any(run.n_steps != 1 or run.batch for run in runs):
            return None
        t0 = runs[0].step_times_s[0]
        if any(run.step_times_s[0] != t0 for run in runs):
            return None
        n = max(max(run.coefficients.shape[-1], 1 if run.sensitivities is None else run.sensitivities.shape[-1])
                for run in runs)
        return t0, n

    def _evaluate(self, t_s, fn, tail):
        shape, flat, parts, _ = self._split(t_s)
        out = np.empty((flat.size,) + tail)
        for run, sel, times in parts:
            out[sel] = fn(run, times)
        return out.reshape(shape + tail)

    def state(self, t_s, *, frame: str = "gcrf", derivative: int = 0) -> np.ndarray:
        """State ``[r (m), v (m/s)]`` at ``t_s`` (s from the epoch, or UTC ``datetime64``),
        shape ``t_s.shape + (6,)``.

        ``frame="gcrf"`` (default) or ``"quasi-inertial"``; ``derivative=1`` gives ``[v, a]``.
        """
        shape, flat, parts, zero = self._split(t_s)
        out = np.empty((flat.size, 6))
        for run, sel, times in parts:
            # the run's products, (1, 2, 3, M): the rows of out, without the run's own reshaping
            rows = (run._dense_rows(run.coefficients, times, derivative, "state")
                    if derivative in (0, 1) and not run.batch and times.size else None)
            out[sel] = run.state(times, derivative) if rows is None else rows.reshape(6, -1).T
        out = out.reshape(shape + (6,))
        if frame == "gcrf" or _frame_key(frame) == "gcrf":
            # both halves (r, v) of every row as rows of one product: r q and v q, one call
            out = (out.reshape(-1, 3) @ self.frame.q).reshape(out.shape)
            if derivative == 0 and self.initial_gcrf is not None and zero is not None:
                out[zero] = self.initial_gcrf                               # the epoch state, unrotated
        return out

    def stm(self, t_s, *, frame: str = "gcrf") -> np.ndarray:
        """State transition matrix ``Phi(t, epoch) = d state(t) / d state(epoch)``, ``(..., 6, 6)``.

        In GCRF (default) ``Phi_gcrf = Q^T Phi_qi Q``; needs ``propagate(..., stm=True)``.

        Implements seed 004 eqs. 19-21 (first-order sensitivities of the spectra).
        """
        if not self.has_stm:
            raise ValueError("this trajectory carries no STM; propagate with stm=True")
        gcrf = frame == "gcrf" or _frame_key(frame) == "gcrf"
        if gcrf:
            out = self._stm_gcrf(t_s)
            if out is not None:
                return out
        out = self._evaluate(t_s, lambda run, t: run.stm(t), (6, 6))
        if gcrf:
            big = self.rotation
            out = big.T @ out @ big
        return out

    def _stm_gcrf(self, t_s):
        """``Q^T Phi Q`` of :meth:`stm` from each run's ``[row, column, time]`` products: the left
        rotation of every matrix is one product over all the times (``Q^T`` times the rows), the
        right one a product for each row (``Q^T`` times its columns), each element the sum of
        the same products in the same order as the rotation of each matrix (equal bit for bit);
        None where a run cannot give that layout or has a single time."""
        shape, flat, parts, _ = self._split(t_s)
        if any(times.size < 2 for _, _, times in parts):
            return None                         # a single column: matrix-vector kernels, other sums
        out = np.empty((flat.size, 6, 6))
        big_t = self.__dict__.get("_rotation_t")
        if big_t is None:
            big_t = self.__dict__["_rotation_t"] = self.rotation.T
        for run, sel, times in parts:
            rows = run.stm_rows(times)
            if rows is None:
                return None
            m = times.size
            left = (big_t @ rows.reshape(6, 6 * m)).reshape(6, 6, m)      # [i, p, n] = (Q^T Phi_n)[i, p]
            out[sel] = (big_t @ left).transpose(2, 0, 1)                  # [i, j, n] = (Q^T Phi_n Q)[i, j]
        return out.reshape(shape + (6, 6))

    @property
    def force_parameter_names(self) -> tuple:
        """Force-model parameters whose partials the runs carry (``cr``, ``cd``, ``empirical_*``)."""
        return tuple(self.runs[0].parameters[6:]) if self.has_stm and self.runs else ()

    def parameter_partials(self, t_s, *, frame: str = "gcrf") -> np.ndarray:
        """``d state(t) / d p`` for :attr:`force_parameter_names`, ``(..., 6, P)`` (GCRF by default)."""
        names = self.force_parameter_names
        if not names:
            raise ValueError("this trajectory carries no force-parameter partials; propagate a ForceModel "
                             "with estimated parameters and stm=True")
        out = self._evaluate(t_s, lambda run, t: run.jacobian(t)[..., 6:], (6, len(names)))
        if _frame_key(frame) == "gcrf":
            out = self.rotation.T @ out
        return out

    def covariance(self, t_s, covariance0) -> np.ndarray:
        """Propagated GCRF covariance ``Phi P0 Phi^T`` (m^2, m^2/s, m^2/s^2), ``(..., 6, 6)``.

        ``covariance0`` is the 6 x 6 GCRF covariance of the epoch state (rows/columns x, y, z,
        vx, vy, vz). Linear propagation (the first-order sensitivities of seed 004 eqs. 19-21),
        the generalisation of seed 000's correlation function to the full state.
        """
        p0 = np.asarray(covariance0, float)
        if p0.shape != (6, 6):
            raise ValueError(f"covariance0 must be 6 x 6; found {p0.shape}")
        phi = self.stm(t_s)
        out = phi @ p0 @ np.swapaxes(phi, -1, -2)
        return 0.5 * (out + np.swapaxes(out, -1, -2))

    def steps(self) -> Steps:
        """All Taylor steps in time order (quasi-inertial frame), for measurement spectra."""
        lo, hi, ex, coef, sens = [], [], [], [], []
        for run in self.runs:
            if not run.n_steps:
                continue
            tb = run.step_times_s
            forward = run.t_end_s >= run.t0_s
            order = range(run.n_steps) if forward else range(run.n_steps - 1, -1, -1)
            for k in order:
                a, b = tb[k], tb[k + 1]
                lo.append(min(a, b))
                hi.append(max(a, b))
                ex.append(a)
                coef.append(run.coefficients[k, 0])
                if run.sensitivities is not None:
                    sens.append(run.sensitivities[k, 0, :, :6])
        if not lo:
            raise ValueError("the trajectory has no steps")
        return Steps(t_lo_s=np.array(lo), t_hi_s=np.array(hi), t_expand_s=np.array(ex),
                     coefficients=np.stack(coef),
                     sensitivities=np.stack(sens) if len(sens) == len(lo) else None)


#: The last offsets and powers :meth:`Trajectory._share_powers` made, ``(key, dt, powers)``.
_LAST_POWERS: list = [None]


def _frame_key(frame: str) -> str:
    key = str(frame).strip().lower().replace("_", "-")
    if key in ("gcrf", "gcrs", "icrf"):
        return "gcrf"
    if key in ("quasi-inertial", "qi", "integration"):
        return "qi"
    raise ValueError(f"unknown frame {frame!r}; expected 'gcrf' or 'quasi-inertial'")


def reference_frame(jd1: float, jd2: float, eop=None) -> QuasiInertialFrame:
    """The quasi-inertial frame of a UTC epoch, with the ERA rate of the Earth orientation
    (``OMEGA_ERA`` times ``1 +`` the UT1 rate of a tabulated EOP)."""
    rot = earth_rotation(jd1, jd2, eop, rates=True)
    return QuasiInertialFrame(ref_jd_utc=(float(np.ravel(jd1)[0]), float(np.ravel(jd2)[0])),
                              q=rot.q[0], w=rot.w[0], era0=float(rot.era[0]), omega=float(rot.omega[0]))


def propagate(r_m, v_m_s, epoch, t_s, *, force: str = "j2", eop=None, tol: float = 1e-15,
              stm: bool = False, frame: QuasiInertialFrame | None = None,
              max_steps: int = 100_000, force_model=None, compiled: bool | None = None) -> Trajectory:
    """Propagate a GCRF state to cover times ``t_s`` (s from ``epoch``, either sign).

    Parameters
    ----------
    r_m, v_m_s : (3,)
        GCRF position (m) and velocity (m/s) at ``epoch``.
    epoch : datetime64 or ISO 8601 text
        UTC epoch of the state.
    t_s : float or array
        Times to cover, SI seconds from the epoch (negative = before it), or UTC
        ``datetime64`` labels. The runs cover ``[min(t_s, 0), max(t_s, 0)]``; evaluate at any
        time inside (:meth:`Trajectory.state` etc. take seconds or ``datetime64`` too).
    force : ``"two-body"``, ``"j2"`` or ``"full"``
        Force model (constants from :mod:`trackproc.constants`); ``"full"`` integrates
        ``force_model`` (a :class:`trackproc.dynamics.forces.ForceModel`, which may also be
        passed as ``force`` itself) with DOP853 and the variational equations
        (:mod:`trackproc.dynamics.forces.integrator`); its STM and the partials of its
        estimated parameters (:meth:`Trajectory.parameter_partials`) come with ``stm``.
    eop : :class:`~trackproc.dynamics.timescales.EarthOrientation` or None
        Earth orientation for the integration frame (only the precession-nutation matrix of
        the reference epoch matters to the dynamics).
    tol : float
        Taylor tolerance per step (combined absolute/relative; down to about 1e-16). For
        ``"full"``: the DOP853 relative tolerance; below DOP853's floor (2.3e-14, e.g. the
        Taylor default 1e-15) ``integrator.RTOL`` (1e-12).
    stm : bool
        Also propagate the state transition matrix (first-order sensitivity spectra).
    frame : QuasiInertialFrame, optional
        Integration frame; default that of ``epoch`` (what the simulator uses).
    max_steps : int
        Per run; beyond it the run stops with outcome ``step_limit``.
    compiled : bool or None
        For ``"full"``: the compiled (True) or numpy (False) DOP853; None chooses from the run's
        span (:func:`trackproc.dynamics.forces.integrator.use_compiled`).

    Returns
    -------
    Trajectory
        Check :attr:`Trajectory.outcome` or call :meth:`Trajectory.raise_for_outcome`.

    Implements seed 000 eq. 14 and seed 004 eqs. 6, 19-21 through
    :func:`trackproc.dynamics.taylor.propagate`.
    """
    if isinstance(epoch, str):
        epoch = np.datetime64(epoch.rstrip("Zz"), "ns")
    epoch = np.datetime64(epoch, "ns")
    jd1, jd2 = ts.datetime64_to_jd_utc(epoch)
    jd = (float(jd1), float(jd2))
    model = None
    if not isinstance(force, str) and hasattr(force, "environment"):
        model, force = force, "full"
    elif force == "full":
        model = force_model
        if model is None:
            raise ValueError("force 'full' needs a force_model (trackproc.dynamics.forces.ForceModel)")
    if model is not None:
        mu, j2, re, key = model.field.gm_m3_s2, model.field.j2(), model.field.radius_m, "full"
    else:
        mu, j2, re = force_parameters(force)
        key = "two-body" if j2 == 0.0 else "j2"
    r = np.asarray(r_m, float).reshape(3)
    v = np.asarray(v_m_s, float).reshape(3)
    if not (np.isfinite(r).all() and np.isfinite(v).all()):
        raise ValueError("the initial state must be finite")
    t = np.atleast_1d(np.asarray(t_s))
    if t.dtype.kind == "M":                      # datetime64 (np.issubdtype's answer, without its cost)
        t = np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(t.astype("datetime64[ns]")), jd), float)
    t = t.astype(float)
    if t.size == 0 or not np.isfinite(t).all():
        raise ValueError("t_s must hold at least one finite time")
    fr = frame if frame is not None else reference_frame(jd[0], jd[1], eop)
    q = fr.q
    s0 = np.concatenate([q @ r, q @ v])
    t_min, t_max = float(min(t.min(), 0.0)), float(max(t.max(), 0.0))
    runs = []
    ends = ([t_min] if t_min < 0.0 else []) + ([t_max if t_max > 0.0 else _MIN_SPAN_S]
                                             if (t_max > 0.0 or t_min == 0.0) else [])
    if model is not None:
        # start-up: the force models (~30 ms of imports) load only when a force model is asked for
        from trackproc.dynamics.forces import integrator

        env = model.environment(jd, q, t_min, max(t_max, _MIN_SPAN_S))
        for end in ends:
            runs.append(integrator.propagate(env, s0, end, stm=stm, rtol=integrator.rtol_for(tol),
                                             max_steps=max_steps, compiled=compiled))
    else:
        for end in ends:
            runs.append(taylor.propagate(s0, 0.0, end, force=key, mu_m3_s2=mu, j2=j2, re_m=re, tol=tol,
                                         stm=stm, max_steps=max_steps))
    return Trajectory(epoch=epoch, epoch_jd_utc=jd, frame=fr, runs=tuple(runs), force=key,
                      mu_m3_s2=mu, j2=j2, re_m=re, tol=float(tol), t_min_s=t_min, t_max_s=t_max,
                      initial_gcrf=np.concatenate([r, v]), force_model=model)


def propagate_state(state, t_s, **kwargs) -> Trajectory:
    """:func:`propagate` from a state object with ``r_m``, ``v_m_s`` (GCRF) and ``epoch``
    (UTC ``datetime64``), e.g. :class:`trackproc.io.statefile.State`."""
    return propagate(state.r_m, state.v_m_s, state.epoch, t_s, **kwargs)


class Restarted:
    """A trajectory propagated from a state at ``start_s`` (s from another epoch), read on that
    epoch's time axis: ``state(t)``, ``stm(t) = Φ(t, start_s)``, ``parameter_partials(t) =
    ∂s(t)/∂p`` at fixed ``s(start_s)`` take and give times in seconds from the axis's epoch
    (``datetime64`` labels pass through as they are absolute). ``traj`` is the
    :class:`Trajectory` propagated from the restart's own UTC epoch (so that time-dependent
    forces see the absolute time); only what the measurement models and the filter read is
    exposed, so that nothing reads the inner trajectory's axis by mistake."""

    def __init__(self, traj: Trajectory, start_s: float):
        self.traj = traj
        self.start_s = float(start_s)

    def _t(self, t_s):
        t = np.asarray(t_s)
        return t if np.issubdtype(t.dtype, np.datetime64) else np.asarray(t, float) - self.start_s

    def state(self, t_s, **kw) -> np.ndarray:
        return self.traj.state(self._t(t_s), **kw)

    def stm(self, t_s, **kw) -> np.ndarray:
        return self.traj.stm(self._t(t_s), **kw)

    def parameter_partials(self, t_s, **kw) -> np.ndarray:
        return self.traj.parameter_partials(self._t(t_s), **kw)

    def seconds(self, times_utc) -> np.ndarray:
        return self.traj.seconds(times_utc) + self.start_s

    def times_utc(self, t_s) -> np.ndarray:
        return self.traj.times_utc(self._t(t_s))

    @property
    def t_min_s(self) -> float:
        return self.traj.t_min_s + self.start_s

    @property
    def t_max_s(self) -> float:
        return self.traj.t_max_s + self.start_s

    @property
    def n_steps(self) -> int:
        return self.traj.n_steps

    @property
    def has_stm(self) -> bool:
        return self.traj.has_stm

    @property
    def force_parameter_names(self) -> tuple:
        return self.traj.force_parameter_names

    @property
    def frame(self):
        return self.traj.frame

    def raise_for_outcome(self) -> "Restarted":
        self.traj.raise_for_outcome()
        return self


def propagate_from(r_m, v_m_s, epoch, start_s: float, t_s, **kwargs) -> Restarted | Trajectory:
    """:func:`propagate` of a GCRF state at ``start_s`` (SI seconds from the UTC ``epoch``) to
    cover times ``t_s`` (s from ``epoch``), as a :class:`Restarted` on ``epoch``'s axis (the plain
    :class:`Trajectory` when ``start_s`` is 0). The run starts at the restart's own UTC time (leap
    seconds counted), so the forces that depend on time see it; pass ``frame`` to keep the
    integration frame of ``epoch``."""
    if start_s == 0.0:
        return propagate(r_m, v_m_s, epoch, t_s, **kwargs)
    if isinstance(epoch, str):
        epoch = np.datetime64(epoch.rstrip("Zz"), "ns")
    jd1, jd2 = ts.add_seconds_utc(ts.datetime64_to_jd_utc(np.datetime64(epoch, "ns")), np.asarray([float(start_s)]))
    start = ts.jd_utc_to_datetime64(jd1, jd2)[0]
    t = np.asarray(t_s, float) - float(start_s)
    return Restarted(propagate(r_m, v_m_s, start, t, **kwargs), start_s)
