"""The filter's noise (docs/filter.md, "Process noise", "Correlated measurement noise"): each pass's
measurement-noise model in sequential form (:func:`pass_noise`: REML's AR(1) as a Gauss–Markov
state of the pass, its walk on the pass's offset), the Gauss–Markov states (:func:`gauss_markov`:
dynamic model compensation and Gauss–Markov biases) and their transition (:func:`gm_transition`),
the per-pass bias resets (:func:`pass_resets`), and the process noise of one step
(:func:`process_noise`). The sweep that uses them is :mod:`trackproc.pipeline.filter.run`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.dynamics.rtn import rtn_rotation
from trackproc.methods import sequential as sq
from trackproc.pipeline.filter.options import FilterOptions
from trackproc.pipeline.od import Problem


@dataclass
class PassNoise:
    """The per-pass measurement noise of the filter in sequential form (:func:`pass_noise`):
    ``sigma`` the white part per sample (the samples' unit), ``column`` per sample the index of
    its pass's AR(1) state among the ``states`` (-1: none), ``states`` ``[(sigma, tau_s), ...]``
    one first-order Gauss–Markov measurement-noise state per pass with an AR(1) component,
    ``walk`` ``{doppler_offset parameter: Hz/√s}`` the transmitter's random walk per pass,
    ``report`` ``{"STATION/PASS": model}`` as ``estimate`` records it."""

    sigma: np.ndarray
    column: np.ndarray
    states: list
    walk: dict
    report: dict


def pass_noise(problem: Problem, opt: FilterOptions, residual=None, keep=None) -> PassNoise | None:
    """The noise model of each pass's Doppler and range-rate samples, chosen as ``estimate`` and
    ``refine`` choose it (:func:`trackproc.methods.noise.fit_noise`: REML among white, AR(1) and,
    for a pass with its own transmitter offset, the offset's random walk; the pass's Jacobian
    columns as fixed effects), on ``residual`` (per sample; default the residuals against the
    initial orbit, the problem's first guess), the samples outside ``keep`` (edited) left out as
    estimate leaves its edited samples out. In sequential form (Bryson & Henrikson 1968; Tapley, Schutz & Born 2004 4.9): the
    AR(1) part ``σ_a² e^{−|Δt|/τ}`` is a first-order Gauss–Markov state added to the pass's
    samples (steady state σ_a, time constant τ; its steady-state prior at the pass's start), the
    random walk a random walk of the pass's offset, the white part the samples' noise. None for
    ``--noise white`` or when no pass has 20 samples."""
    from trackproc.methods import noise as nz

    popt = opt.problem
    if popt.noise == "white":
        return None
    meas = problem.meas
    rr = np.isin(meas.kind, ["doppler", "range_rate"])
    if not rr.any():
        return None
    h, jac = problem.model(np.asarray(problem.x0, float))
    r = np.asarray(meas.observed, float) - np.asarray(h, float) if residual is None else np.asarray(residual, float)
    keep = np.ones(r.size, bool) if keep is None else np.asarray(keep, bool)
    sigma = np.asarray(meas.sigma, float).copy()
    column = np.full(sigma.size, -1)
    states, walk, report = [], {}, {}
    names = problem.names
    given = opt.bias_walk.get("doppler_offset")
    two_way = np.asarray(getattr(meas, "two_way", np.zeros(sigma.size, bool)), bool)
    for st, pid in sorted(set(zip(np.asarray(meas.station)[rr].astype(str), np.asarray(meas.pass_id)[rr].astype(str)))):
        rows = np.flatnonzero(rr & (np.asarray(meas.station).astype(str) == st) & (np.asarray(meas.pass_id).astype(str) == pid))
        if rows.size < 20:
            continue
        rows = rows[np.argsort(meas.t_s[rows], kind="stable")]
        used = rows[keep[rows]]
        if used.size < 20:
            continue
        offset = next((f"doppler_offset:{k}" for k in (pid, st) if f"doppler_offset:{k}" in names), None)
        osc = offset is not None and not two_way[rows].any()
        gwalk = opt.bias_walk.get(offset, given) if osc else None
        t = meas.t_s[rows]
        nf = nz.fit_noise(meas.t_s[used], r[used], np.asarray(jac, float)[used],
                          models=nz.candidate_models(popt.noise, osc), walk=gwalk, t0=float(t.min()))
        d = nf.as_dict()
        d.pop("candidates", None)
        report[f"{st}/{pid}"] = d
        m = nf.model
        if m.is_white:
            continue
        sigma[rows] = m.white
        if m.ar_sigma > 0 and m.ar_tau_s > 0:
            column[rows] = len(states)
            states.append((float(m.ar_sigma), float(m.ar_tau_s)))
        if m.walk > 0 and osc and gwalk is None:
            walk[offset] = float(m.walk)
    if not report:
        return None
    return PassNoise(sigma=sigma, column=column, states=states, walk=walk, report=report)


#: The force parameters dynamic model compensation turns into Gauss–Markov states (R, T, N).
DMC_NAMES = ("empirical_r", "empirical_t", "empirical_n")


def gauss_markov(problem: Problem, opt: FilterOptions) -> dict:
    """``{index: (sigma, tau, is_acceleration)}`` of the parameters that are first-order
    Gauss–Markov processes: the empirical RTN accelerations under ``opt.dmc`` and the biases
    named in ``opt.bias_gm``. :class:`InputError` when ``--dmc`` has no empirical acceleration
    to act on, or a ``--bias-gm`` name matches no bias."""
    from trackproc.errors import InputError
    from trackproc.pipeline.filter.options import WALK_FAMILIES

    out = {}
    names = problem.names
    if opt.dmc is not None:
        missing = [n for n in DMC_NAMES if n not in names]
        if missing:
            raise InputError("dynamic model compensation needs the empirical RTN acceleration as a state",
                             column="--dmc", found="no " + ", ".join(missing),
                             expected="--force full with --estimate-force empirical-rtn")
        for axis, n in enumerate(DMC_NAMES):
            out[names.index(n)] = (float(opt.dmc[axis]), float(opt.dmc[3]), True)
    used = set()
    for i, d in enumerate(problem.params.selected):
        key = d.name if d.name in opt.bias_gm else d.family if d.family in opt.bias_gm else None
        if key is None:
            continue
        if d.family not in WALK_FAMILIES:
            raise InputError("only a bias can be a Gauss-Markov bias", column="--bias-gm", found=key,
                             expected="a family of " + ", ".join(WALK_FAMILIES) + " or one such parameter")
        sigma, tau = opt.bias_gm[key]
        out[i] = (float(sigma), float(tau), False)
        used.add(key)
    unused = sorted(set(opt.bias_gm) - used)
    if unused:
        raise InputError("no estimated bias of that name", column="--bias-gm", found=", ".join(unused),
                         expected="a bias family (range_bias, doppler_offset, ...) or parameter the problem estimates")
    return out


def noise_states(problem: Problem, opt: FilterOptions, noise: PassNoise | None) -> dict:
    """:func:`gauss_markov` with the passes' AR(1) measurement-noise states (:func:`pass_noise`),
    which follow the problem's parameters in the filter's state."""
    gm = gauss_markov(problem, opt)
    if noise is not None:
        n_par = len(problem.names)
        gm.update({n_par + j: (sigma, tau, False) for j, (sigma, tau) in enumerate(noise.states)})
    return gm


#: Bias families ``--bias-reset-per-pass`` may name (per-station biases).
RESET_FAMILIES = ("range_bias", "az_bias", "el_bias")


def pass_resets(problem: Problem, opt: FilterOptions) -> dict:
    """``{time s: [parameter index, ...]}``: the per-station biases named in ``opt.bias_reset``
    restart from their a-priori at the first sample of each of their station's passes after its
    first. :class:`InputError` for a name that is not such a bias."""
    from trackproc.errors import InputError

    if not opt.bias_reset:
        return {}
    by_station, used = {}, set()
    for i, d in enumerate(problem.params.selected):
        key = d.name if d.name in opt.bias_reset else d.family if d.family in opt.bias_reset else None
        if key is None:
            continue
        if d.family not in RESET_FAMILIES:
            raise InputError("only a per-station bias can be reset per pass", column="--bias-reset-per-pass",
                             found=key, expected="one of " + ", ".join(RESET_FAMILIES) + " or such a parameter")
        by_station.setdefault(d.name.split(":", 1)[1], []).append(i)
        used.add(key)
    unused = sorted(set(opt.bias_reset) - used)
    if unused:
        raise InputError("no estimated per-station bias of that name", column="--bias-reset-per-pass",
                         found=", ".join(unused), expected="range_bias, az_bias, el_bias or one such parameter")
    meas = problem.meas
    station, pass_id, t = np.asarray(meas.station).astype(str), np.asarray(meas.pass_id).astype(str), meas.t_s
    out = {}
    for st, idx in by_station.items():
        rows = station == st
        starts = sorted({float(t[rows & (pass_id == pid)].min()) for pid in set(pass_id[rows])})
        for t0 in starts[1:]:
            out.setdefault(t0, []).extend(idx)
    return out


def gm_transition(phi: np.ndarray, dt, gm: dict) -> np.ndarray:
    """``phi`` (Ψ over a forward step ``dt``, the parameters constants of the reference) with the
    Gauss–Markov states' transition: ``e^{−dt/τ}`` on their diagonal and, for an acceleration,
    its columns of the orbit's rows (a constant acceleration's effect over the step, from the
    problem's own partials) scaled to a decaying one's (:func:`~trackproc.methods.sequential.gm_transition`).
    ``phi`` one matrix (n, n) and ``dt`` a number, or a stack of steps (m, n, n) and their ``dt``
    (m,): a segment's steps in one call, the factors computed once per distinct step length.
    In place; scaling of the variables leaves both unchanged."""
    dt = np.asarray(dt, float)
    lengths, which = np.unique(dt.reshape(-1), return_inverse=True)
    for i, (_, tau, accel) in gm.items():
        f = np.array([sq.gm_transition(d, tau) for d in lengths])[which].reshape(dt.shape + (3,))
        if accel:
            phi[..., :3, i] *= f[..., 0, None]
            phi[..., 3:6, i] *= f[..., 1, None]
        phi[..., i, i] = f[..., 2]
    return phi


def process_noise(problem: Problem, opt: FilterOptions, dt: float, z_abs, scales, gm=None) -> np.ndarray | None:
    """Q over ``dt`` (scaled variables) at the reference state ``z_abs``: one step of
    :func:`process_noise_steps`; None when ``dt ≤ 0`` or nothing is noisy."""
    if not dt > 0:
        return None
    q = process_noise_steps(problem, opt, np.array([float(dt)]), np.asarray(z_abs, float)[None], scales, gm)
    return None if q is None else q[0]


def process_noise_steps(problem: Problem, opt: FilterOptions, dt, z_abs, scales, gm=None) -> np.ndarray | None:
    """Q over each of the steps ``dt`` (m,), all > 0, ending at the reference states ``z_abs``
    (m, n), as (m, n, n) in scaled variables; None when nothing is noisy. State noise
    compensation in RTN (:func:`~trackproc.methods.sequential.snc_noise`, rotated to GCRF at the
    reference state), the random walks of the biases (``q² dt``), and the Gauss–Markov states
    ``gm`` (:func:`gauss_markov`): a bias ``σ²(1 − e^{−2dt/τ})``, an empirical acceleration
    DMC's exact noise on (position, velocity, acceleration) per RTN axis
    (:func:`~trackproc.methods.sequential.dmc_noise`), its position and velocity rotated to GCRF.
    The steps of a segment at once: the sweep's per-step cost was these small products; each
    step's Q is the same numbers as alone."""
    dt = np.asarray(dt, float)
    m, n = dt.size, scales.size
    q = np.zeros((m, n, n))
    any_noise = False
    acc = np.asarray(opt.snc_accel, float)
    rot = None

    def axes():
        return rot if rot is not None else rtn_rotation(z_abs[:, :3], z_abs[:, 3:6])   # rows R, T, N in GCRF

    if acc.any():
        rot = axes()
        psd = rot.transpose(0, 2, 1) @ np.diag(acc ** 2) @ rot
        q[:, :6, :6] = [sq.snc_noise(d, c) for d, c in zip(dt, psd)]
        any_noise = True
    if opt.bias_walk:
        for i, d in enumerate(problem.params.selected):
            rate = opt.bias_walk.get(d.name, opt.bias_walk.get(d.family))
            if rate:
                q[:, i, i] += rate ** 2 * dt
                any_noise = True
    if gm:
        blocks = {}                            # per (sigma, tau, dt): the axes and steps share most
        for i, (sigma, tau, accel) in gm.items():
            if not accel:
                q[:, i, i] += [sq.gm_bias_noise(d, tau, sigma) for d in dt]
                continue
            rot = axes()
            u = rot[:, DMC_NAMES.index(problem.names[i])]      # this axis in GCRF (m, 3)
            b = []
            for d in dt.tolist():
                if (sigma, tau, d) not in blocks:
                    blocks[(sigma, tau, d)] = sq.dmc_noise(d, tau, sigma)
                b.append(blocks[(sigma, tau, d)])
            b = np.array(b)
            uu = u[:, :, None] * u[:, None, :]
            q[:, :3, :3] += b[:, 0, 0, None, None] * uu
            q[:, :3, 3:6] += b[:, 0, 1, None, None] * uu
            q[:, 3:6, :3] += b[:, 0, 1, None, None] * uu
            q[:, 3:6, 3:6] += b[:, 1, 1, None, None] * uu
            q[:, :3, i] += b[:, 0, 2, None] * u
            q[:, i, :3] += b[:, 0, 2, None] * u
            q[:, 3:6, i] += b[:, 1, 2, None] * u
            q[:, i, 3:6] += b[:, 1, 2, None] * u
            q[:, i, i] += b[:, 2, 2]
        any_noise = True
    if not any_noise:
        return None
    return q / np.outer(scales, scales)
