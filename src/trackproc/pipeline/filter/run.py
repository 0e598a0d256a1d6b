"""One run of the filter over a :class:`Problem`: the sweep (:func:`sweep`: an extended Kalman
filter linearised about a reference trajectory that restarts from the filter's state at each
tracking segment), the smoother (:func:`smooth`) and the iterated run (:func:`run`), with the
passes' noise models fitted on a first white run (:func:`fitted_noise`); the noise models, the
Gauss–Markov states and the process noise themselves are in :mod:`trackproc.pipeline.filter.noise`.
One responsibility, the filter's recursion; its length is the sweep's (:func:`sweep`, whose
steps share the reference, the scaled state and the restart bookkeeping).

Variables are scaled by the drivers' scales inside (``ξ = x / scale``) so that metres, m/s, Hz
and force coefficients share one well-conditioned covariance; everything returned is in the
parameters' own units.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from trackproc.errors import InputError
from trackproc.methods import sequential as sq
from trackproc.pipeline.filter.options import DIFFUSE_SCALES, FilterOptions
from trackproc.pipeline.filter.noise import (PassNoise, gauss_markov, gm_transition, noise_states,
                                              pass_noise, pass_resets, process_noise_steps)
from trackproc.pipeline.od import Problem


#: the velocity's share of the "settled" test: its sigma over this many seconds (a quarter of a
#: LEO revolution) counts as position
EKF_HORIZON_S = 1000.0


@dataclass
class Sweep:
    """One pass of the filter (and, after :func:`smooth`, the smoother) over the steps.

    Per step k (time ``t_s[k]``, s from the problem's epoch): predicted ``x_p``, ``p_p``,
    filtered ``x_f``, ``p_f``, the transition ``phi[k] = Ψ(t_k, t_{k-1})``, the reference state
    ``z_ref[k]``; smoothed ``x_s``, ``p_s`` (None before :func:`smooth`). Per sample (the
    problem's order): ``step``, ``innovation`` (y − predicted, before its update), ``variance``
    (its innovation variance), ``edited``, and the linearisation (``h_ref``, ``h_row``) for the
    post-fit residuals. All in scaled variables (``scales``)."""

    t_s: np.ndarray
    scales: np.ndarray
    x_p: np.ndarray
    p_p: np.ndarray
    x_f: np.ndarray
    p_f: np.ndarray
    phi: np.ndarray
    z_ref: np.ndarray
    step: np.ndarray
    innovation: np.ndarray
    variance: np.ndarray
    edited: np.ndarray
    h_ref: np.ndarray
    h_row: np.ndarray
    segments: list
    x_s: np.ndarray | None = None
    p_s: np.ndarray | None = None
    evaluations: int = 0
    #: the reference's integration work over the sweep: Taylor/DOP853 steps and seconds propagated
    integrated_steps: int = 0
    propagated_s: float = 0.0

    @property
    def epoch_step(self) -> int:
        """The step at the problem's epoch (t = 0, where the a-priori applies); steps before it
        are the samples older than the epoch."""
        return int(np.flatnonzero(self.t_s == 0.0)[0])

    def absolute(self, which: str, k: int):
        """``(x, P)`` of step k in the parameters' units; ``which`` is ``f``, ``p`` or ``s``."""
        x = getattr(self, "x_" + which)[k] * self.scales
        p = getattr(self, "p_" + which)[k] * np.outer(self.scales, self.scales)
        return x, p

    def residuals(self, which: str = "f") -> np.ndarray:
        """Post-fit residuals of every sample on the filtered (``f``, after its step's updates) or
        smoothed (``s``) states, through the linearisation of its step."""
        x = getattr(self, "x_" + which)[self.step]
        dz = x - self.z_ref[self.step]
        return self.h_obs - self.h_ref - np.einsum("ij,ij->i", self.h_row, dz)

    h_obs: np.ndarray = field(default=None)


def initial_covariance(problem: Problem, carried=None, gm=None):
    """The filter's start: ``(centre, P0)`` over the problem's parameters from its priors
    (the initial state's covariance or ``--apriori-sigma``), a diffuse sigma
    (:data:`DIFFUSE_SCALES` × scale) for a parameter without one; ``carried``: a previous run's
    state (same epoch) whose values and covariance replace those of the parameters it shares;
    ``gm`` (:func:`gauss_markov`): a Gauss–Markov state without a prior starts at its
    steady-state sigma.
    :class:`InputError` when nothing gives the orbit state an uncertainty."""
    names = problem.names
    scales = problem.params.scales()
    centre = problem.x0.astype(float).copy()
    p0 = np.diag((DIFFUSE_SCALES * scales) ** 2)
    has = np.zeros(len(names), bool)
    for prior in problem.priors:
        idx = np.asarray(prior.index, int)
        p0[idx, :] = 0.0
        p0[:, idx] = 0.0
        p0[np.ix_(idx, idx)] = np.asarray(prior.covariance, float)
        centre[idx] = np.asarray(prior.centre, float)
        has[idx] = True
    for i, (sigma, _, _) in (gm or {}).items():
        if not has[i]:
            p0[i, i] = sigma * sigma
    if carried is not None and carried.covariance is not None:
        shared = [n for n in carried.parameters if n in names]
        src = [carried.parameters.index(n) for n in shared]
        dst = [names.index(n) for n in shared]
        p0[dst, :] = 0.0
        p0[:, dst] = 0.0
        p0[np.ix_(dst, dst)] = np.asarray(carried.covariance, float)[np.ix_(src, src)]
        if carried.values is not None:
            centre[dst] = np.asarray(carried.values, float)[src]
        has[dst] = True
    if not has[:6].all():
        raise InputError("the filter needs the initial state's uncertainty", column="--initial",
                         found="a state without covariance",
                         expected="a state file with a covariance, --apriori-sigma position=M velocity=M/S, "
                                  "or --apriori-initial")
    return centre, p0


def _sub_problem(problem: Problem, rows) -> Problem:
    """The problem restricted to ``rows`` (same parameters and epoch; the modifiers bound again,
    those acting on none of the rows dropped)."""
    meas = problem.meas.subset(rows)
    bound = []
    for b in problem.modifiers:
        try:
            bound.append(b.modifier.bind(meas))
        except ValueError:
            continue
    return replace(problem, meas=meas, modifiers=bound, times=problem.times[rows], sources=problem.sources[rows])


def _evaluate(sub: Problem, x, cover=(), start_s: float = 0.0):
    """``(h, J, trajectory)`` of the sub-problem at ``x`` (the state at ``start_s``, s from the
    epoch, and the other parameters): the problem's own model, its trajectory (over the samples
    and the times ``cover``) kept; J is with respect to the state at ``start_s``."""
    kept = {}
    own = sub.trajectory

    def recording(xx):
        kept["traj"] = own(xx, cover, start_s=start_s)
        return kept["traj"]

    sub.trajectory = recording
    try:
        h, jac = sub.model(x)
    except ArithmeticError as exc:
        from trackproc.errors import ProcessingError

        raise ProcessingError(f"the reference trajectory failed: {exc}") from None
    return h, jac, kept["traj"]


def _transition(traj, t, n: int) -> np.ndarray:
    """Ψ(t, t_a) of the extended state (n × n), t_a the trajectory's anchor (the epoch, or its
    restart): ``[Φ | ∂s/∂p]`` on the orbit's rows, identity on the parameters' (biases and force
    coefficients are constants of the reference)."""
    t = np.atleast_1d(np.asarray(t, float))
    top = traj.stm(t)                           # (m, 6, 6 + P)
    out = np.broadcast_to(np.eye(n), (t.size, n, n)).copy()
    out[:, :6, :top.shape[-1]] = top
    return out


def _segments(t: np.ndarray, gap: float) -> list:
    """``[(first step, last step), ...]``: runs of steps without a gap longer than ``gap``."""
    cut = np.flatnonzero(np.diff(t) > gap) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut - 1, [t.size - 1]])
    return list(zip(starts.tolist(), ends.tolist()))


#: The first white smoother of :func:`fitted_noise` edits at this multiple of ``--edit-sigma``:
#: generous, since white noise at the samples' sigma understates a correlated pass's innovation
#: variance, and editing that pass would leave REML its few samples near the first guess.
FIRST_EDIT_FACTOR = 4.0


def fitted_noise(problem: Problem, opt: FilterOptions, carried=None) -> PassNoise | None:
    """The passes' noise models (:func:`pass_noise`) fitted on residuals that do not carry the
    initial orbit's error, in every mode: those of a first, white, smoother over the run (zero
    measurement correlation; the run's process noise, a-priori and ``--iterations``; editing at
    :data:`FIRST_EDIT_FACTOR` × ``--edit-sigma``, the edited samples left out of REML), as
    ``estimate`` fits them on its weighted fit's residuals. With zero process noise the smoother
    is the weighted least-squares fit of the whole run linearised about the reference, so each
    pass's residuals are against one orbit fitted to every pass, where the residuals against a
    stale first guess (a TLE) carry its along-track error, which REML may take for white noise
    or for a walk. None when every pass is white or nothing is Doppler/range-rate."""
    meas = problem.meas
    rr = np.isin(meas.kind, ["doppler", "range_rate"])
    if opt.problem.noise == "white" or not rr.any():
        return None
    ids = np.char.add(np.asarray(meas.station).astype(str), "/" + np.asarray(meas.pass_id).astype(str))
    if np.unique(ids[rr], return_counts=True)[1].max() < 20:
        return None
    edit = None if not opt.edit_sigma else FIRST_EDIT_FACTOR * opt.edit_sigma
    white, _ = run(problem, replace(opt, smooth=True, edit_sigma=edit), carried)
    return pass_noise(problem, opt, white.residuals("s"), keep=~white.edited)


def sweep(problem: Problem, x_ref0, centre, p0, opt: FilterOptions, targets=None, restarts: bool = True,
          noise: PassNoise | None = None) -> Sweep:
    """The filter over every measurement time in order (samples at one reception time as
    sequential scalar updates, their noise independent). The reference trajectory starts at
    ``x_ref0`` (the problem's epoch) and restarts at each tracking segment through the filtered
    state at the segment's previous step, or ``targets[k]`` (a previous sweep's smoothed states,
    absolute) when given; between references the filter works on deviations, so no information
    is lost at a restart. ``noise`` (:func:`pass_noise`): the passes' AR(1) noise states follow
    the problem's parameters in the state (``x_ref0``, ``centre``, ``p0`` include them), the
    samples' white sigma replaces theirs. Scaled variables inside.

    Over 100 lines on purpose: one recursion whose stages (the reference restarted, a segment's
    model evaluated, the time update, the scalar updates with editing, the relinearisation) read
    and write the same step arrays, the reference and the latch; split, each would pass a dozen of
    them at every step, and the order of the recursion is what a reader checks against Tapley,
    Schutz & Born (2004) 4.7."""
    meas = problem.meas
    n_par = len(problem.names)
    n_noise = 0 if noise is None else len(noise.states)
    scales = np.concatenate([problem.params.scales(), np.ones(n_noise)])
    n = scales.size
    ss = np.outer(scales, scales)
    steps_t = np.unique(np.concatenate([[0.0], meas.t_s]))
    m = steps_t.size
    step = np.searchsorted(steps_t, meas.t_s)
    order = np.lexsort((np.arange(step.size), step))
    segments = _segments(steps_t, opt.segment_gap_s)
    x_p, x_f, z_ref = (np.zeros((m, n)) for _ in range(3))
    p_p, p_f, phi = (np.zeros((m, n, n)) for _ in range(3))
    nobs = step.size
    innovation, variance = np.full(nobs, np.nan), np.full(nobs, np.nan)
    edited = np.zeros(nobs, bool)
    h_ref, h_row = np.zeros(nobs), np.zeros((nobs, n))
    y = np.asarray(meas.observed, float)
    r2 = np.asarray(meas.sigma if noise is None else noise.sigma, float) ** 2
    noise_col = None if not n_noise else noise.column
    periodic = np.asarray(meas.periodic, bool)
    edit2 = (opt.edit_sigma ** 2) if opt.edit_sigma else np.inf
    gm = noise_states(problem, opt, noise)
    gm_idx = np.array(sorted(gm), int)
    resets = {int(np.searchsorted(steps_t, t0)): idx for t0, idx in pass_resets(problem, opt).items()}
    x_ref = np.asarray(x_ref0, float).copy()
    t_anchor = 0.0                  # x_ref[:6] is the reference's state at this time (s from the epoch)
    # a Gauss-Markov state's reference is its zero mean: the filter's value is then the deviation
    # the transition e^{-dt/tau} decays (a constant reference would make it decay to that value)
    x_ref[gm_idx] = 0.0
    c0, P0 = np.asarray(centre, float) / scales, np.asarray(p0, float) / ss
    evaluations, integrated_steps, propagated_s = 0, 0, 0.0
    chunks = [(ka, kb, seg > 0) for seg, (ka, kb) in enumerate(segments)]
    if problem.compiled is None:
        # the chunks integrate the arc once between them: the full model's integrator chosen once
        # for it (the chunks' sub-problems inherit it)
        problem = replace(problem, compiled=problem.compiled_for(steps_t[-1] - steps_t[0]))
    last_traj = None
    limit = np.inf if opt.ekf_sigma_m is None else float(opt.ekf_sigma_m)

    latched = [False]

    def settled(pk):
        if not restarts:
            return False
        # the filter's state is trusted as a reference once its position sigma is below the limit;
        # before, it is a linearised filter about the current reference (Tapley et al. 2004 4.7.3:
        # the extended filter from a poor first guess diverges, so start it once the covariance has
        # converged). Once started it stays extended: the covariance grows again through a gap or
        # under process noise, and a reference no longer restarted drifts with its first guess's
        # energy error (kilometres a day) while the filter stays linearised about it.
        if not latched[0]:
            var = np.diag(pk)[:6] * scales[:6] ** 2
            latched[0] = float(np.sqrt(var[:3].sum()) + EKF_HORIZON_S * np.sqrt(var[3:].sum())) < limit
        return latched[0]

    while chunks:
        ka, kb, restart = chunks.pop(0)
        rows = order[(step[order] >= ka) & (step[order] <= kb)]
        kprev = ka - 1
        if kprev >= 0:
            target = None
            if restart and settled(p_f[kprev]):
                target = (x_f[kprev] if targets is None else np.asarray(targets[kprev], float) / scales) * scales
            # the chunk's reference starts at its previous step, from the filter's state there (a
            # restart) or the current reference's (the same orbit): integrated over the chunk alone,
            # so the sweep's integration grows with the arc, not with its square. Every use of the
            # transition below is relative to the anchor (Ψ(t_k) Ψ(t_k-1)⁻¹, J Ψ(t_k)⁻¹).
            t_anchor = float(steps_t[kprev])
            if target is not None:
                x_ref = target
                x_ref[gm_idx] = 0.0
            else:
                x_ref = np.concatenate([last_traj.state(t_anchor), x_ref[6:]])
        t_need = steps_t[max(kprev, 0):kb + 1]
        if rows.size:
            sub = _sub_problem(problem, np.sort(rows))
            h, jac, traj = _evaluate(sub, x_ref[:n_par], cover=t_need, start_s=t_anchor)
            evaluations += 1
            pos = np.searchsorted(np.sort(rows), rows)         # rows (time order) -> sub's order
            h, jac = h[pos], jac[pos]
        else:
            traj = problem.trajectory(x_ref[:n_par], cover=t_need, start_s=t_anchor)
            h, jac = np.zeros(0), np.zeros((0, n_par))
        last_traj = traj
        integrated_steps += traj.n_steps
        propagated_s += traj.t_max_s - traj.t_min_s
        psi = _transition(traj, t_need, n) * scales[None, None, :] / scales[None, :, None]
        z_abs = np.concatenate([traj.state(t_need), np.broadcast_to(x_ref[6:], (t_need.size, n - 6))], axis=1)
        z = z_abs / scales
        # the process noise, transitions Ψ(t_k) Ψ(t_{k-1})⁻¹ and inverses Ψ(t_k)⁻¹ of the segment's
        # steps in one call each, not one per step (stacked LAPACK calls: the same per matrix)
        qs = process_noise_steps(problem, opt, np.diff(t_need), z_abs[1:], scales, gm) if t_need.size > 1 else None
        steps_phi = np.linalg.solve(psi[:-1].transpose(0, 2, 1), psi[1:].transpose(0, 2, 1)).transpose(0, 2, 1)
        psi_inv = np.linalg.inv(psi)
        if gm:
            gm_transition(steps_phi, np.diff(t_need), gm)
        off = 0 if kprev < 0 else 1                            # index of step ka in t_need
        if noise_col is not None:
            # a sample's AR(1) noise state enters it with coefficient 1 (the samples' unit)
            extra = np.zeros((rows.size, n_noise))
            col = noise_col[rows]
            has = col >= 0
            extra[np.flatnonzero(has), col[has]] = 1.0
            jac = np.hstack([np.asarray(jac, float).reshape(rows.size, n_par), extra])
        jac = jac * scales[None, :]
        # the samples' indices and steps as Python ints: the loop below reads them once per sample
        rows_at, steps_at = rows.tolist(), step[rows].tolist()
        cursor = 0
        for k in range(ka, kb + 1):
            j = k - ka + off
            z_ref[k] = z[j]
            if k == 0:
                # the a-priori belongs to the epoch (t = 0); samples before it start the filter
                # earlier, with the prior mapped back through the reference's transition (exact
                # without process noise: the same information at the epoch)
                x = z[j] + psi[j] @ (c0 - x_ref / scales)
                p = psi[j] @ P0 @ psi[j].T
                p = 0.5 * (p + p.T)
                phi[k] = np.eye(n)
            else:
                phi[k] = steps_phi[j - 1]                               # Ψ(t_k) Ψ(t_{k-1})⁻¹
                x = z[j] + phi[k] @ (x_f[k - 1] - z[j - 1])
                p = phi[k] @ p_f[k - 1] @ phi[k].T
                if qs is not None:
                    p += qs[j - 1]
                p += p.T
                p *= 0.5
                for i in resets.get(k, ()):
                    # a new pass: the bias forgets its past (a zero row of the transition) and
                    # restarts from its a-priori, as if drawn anew
                    phi[k][i, :] = 0.0
                    x[i] = c0[i]
                    p[i, :] = 0.0
                    p[:, i] = 0.0
                    p[i, i] = P0[i, i]
            x_p[k], p_p[k] = x, p
            inv, z_j = psi_inv[j], z[j]
            while cursor < len(rows_at) and steps_at[cursor] == k:
                i = rows_at[cursor]
                row = jac[cursor] @ inv
                h_ref[i], h_row[i] = h[cursor], row
                nu = y[i] - h[cursor] - row @ (x - z_j)
                if periodic[i]:
                    nu = (nu + np.pi) % (2 * np.pi) - np.pi
                s = float(row @ p @ row) + r2[i]
                innovation[i], variance[i] = nu, s
                if nu * nu > edit2 * s:
                    edited[i] = True
                else:
                    x, p, _ = sq.scalar_update(x, p, row, nu, r2[i])
                cursor += 1
            x_f[k], p_f[k] = x, p
            trusted = settled(p)                               # latches once converged
            moved = x if targets is None else np.asarray(targets[k], float) / scales
            if k < kb and trusted and np.linalg.norm((moved[:3] - z_j[:3]) * scales[:3]) > opt.relinearise_m:
                # the state left the reference by more than its linearisation holds: restart it here
                chunks.insert(0, (k + 1, kb, True))
                break
    out = Sweep(t_s=steps_t, scales=scales, x_p=x_p, p_p=p_p, x_f=x_f, p_f=p_f, phi=phi, z_ref=z_ref, step=step,
                innovation=innovation, variance=variance, edited=edited, h_ref=h_ref, h_row=h_row,
                segments=segments, evaluations=evaluations, integrated_steps=integrated_steps,
                propagated_s=propagated_s)
    out.h_obs = y
    return out


def smooth(sw: Sweep) -> Sweep:
    """The Rauch–Tung–Striebel smoother over the sweep's steps (:func:`~trackproc.methods.sequential.rts_step`)."""
    m = sw.t_s.size
    x_s, p_s = sw.x_f.copy(), sw.p_f.copy()
    # the gains depend on the filter's quantities only: all of them in one stacked call
    gains = sq.rts_gain(sw.p_f[:-1], sw.p_p[1:], sw.phi[1:])
    for k in range(m - 2, -1, -1):
        x_s[k], p_s[k] = sq.rts_step(sw.x_f[k], sw.p_f[k], sw.x_p[k + 1], sw.p_p[k + 1], sw.phi[k + 1],
                                     x_s[k + 1], p_s[k + 1], gain=gains[k])
    sw.x_s, sw.p_s = x_s, p_s
    return sw


def run(problem: Problem, opt: FilterOptions, carried=None, noise: PassNoise | None = None,
        state_scale: float = 1.0) -> tuple[Sweep, list]:
    """The filter (and smoother) over the problem, iterated ``opt.iterations`` times at most: each
    later sweep linearised about the previous one's smoothed states, the prior kept; stops when
    the smoothed start moves less than ``opt.tolerance_sigma`` of its sigma. ``noise``
    (:func:`pass_noise`): the passes' correlated noise as states (steady-state prior) and the
    offsets' random walks; the returned sweep carries the problem's parameters only (the noise
    states dropped, so that residuals are against the deterministic model). Returns the last
    sweep and the history of ``{"sweep", "max_change_sigma"}``. ``state_scale``: the start's state
    covariance scaled by it (its cross-covariance with the other parameters by its root), the
    a-priori's variance component (pipeline/filter/policy.py)."""
    if noise is not None and noise.walk:
        opt = replace(opt, bias_walk={**opt.bias_walk, **noise.walk})
    gm = noise_states(problem, opt, noise)
    centre, p0 = initial_covariance(problem, carried, gauss_markov(problem, opt))
    if state_scale != 1.0:
        d = np.ones(p0.shape[0])
        d[:6] = np.sqrt(state_scale)
        p0 = p0 * np.outer(d, d)
    n_noise = 0 if noise is None else len(noise.states)
    if n_noise:
        centre = np.concatenate([centre, np.zeros(n_noise)])
        p0 = np.block([[p0, np.zeros((p0.shape[0], n_noise))],
                       [np.zeros((n_noise, p0.shape[0])), np.diag([s * s for s, _ in noise.states])]])
    # without process noise the smoothed states are one trajectory, the smoothed epoch state's:
    # later sweeps are linearised about it alone (Gauss-Newton on the batch problem), which does
    # not lean on the first sweep's states where its linearisation was poor
    noisy = any(opt.snc_accel) or any(opt.bias_walk.values()) or bool(gm) or bool(opt.bias_reset)
    x_ref, targets = centre.copy(), None
    history = []
    sw = None
    for it in range(opt.iterations):
        sw = sweep(problem, x_ref, centre, p0, opt, targets, restarts=it == 0 or noisy, noise=noise)
        if opt.smooth:
            smooth(sw)
        if it == opt.iterations - 1:
            break
        x_new, p_new = sw.absolute("s", sw.epoch_step)
        change = float(np.max(np.abs(x_new - x_ref) / np.sqrt(np.diag(p_new))))
        history.append({"sweep": it + 1, "max_change_sigma": change})
        if change < opt.tolerance_sigma:
            break
        x_ref = x_new
        targets = sw.x_s * sw.scales
    if n_noise:
        sw = _without_noise_states(sw, len(problem.names))
    return sw, history


def _without_noise_states(sw: Sweep, n: int) -> Sweep:
    """The sweep on its first ``n`` variables (the problem's parameters)."""
    def cut(a, square):
        if a is None:
            return None
        return a[:, :n, :n] if square else a[..., :n]

    out = replace(sw, scales=sw.scales[:n], x_p=cut(sw.x_p, False), p_p=cut(sw.p_p, True), x_f=cut(sw.x_f, False),
                  p_f=cut(sw.p_f, True), phi=cut(sw.phi, True), z_ref=cut(sw.z_ref, False), h_row=cut(sw.h_row, False),
                  x_s=cut(sw.x_s, False), p_s=cut(sw.p_s, True))
    out.h_obs = sw.h_obs
    return out
