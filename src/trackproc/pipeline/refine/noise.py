"""The noise model of a refinement's pass (REML among white, AR(1), the oscillator's random walk
and both: :mod:`trackproc.methods.noise`) and the transmitter drift a one-way pass wants, then the
GLS solve with them (:func:`solve_noise`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from trackproc.methods import noise as nz
from trackproc.methods.least_squares import prior_rhs, prior_rows
from trackproc.models import modifiers as md
from trackproc.pipeline.refine.assemble import prepare
from trackproc.pipeline.refine.gates import solve_weighted
from trackproc.pipeline.refine.problem import Refinement, link_mode


#: A drift is added to a one-way pass's offset when its GLS estimate exceeds this many sigmas
#: (and √(ln n), the BIC threshold): p = 0.001, so that a pass without drift keeps the offset alone.
DRIFT_T = 3.29


def oscillator_link(ref: Refinement) -> bool:
    """A one-way link with a transmitter offset: the frequency can wander (:meth:`Refinement.oscillator_link`)."""
    return ref.oscillator_link()


def noise_model(ref: Refinement, sol, sigma_scale: float = 1.0) -> tuple[Refinement, bool]:
    """The noise model of the pass from the residuals of a fit ``sol`` (:func:`trackproc.methods.noise.fit_noise`:
    REML, the fixed effects being the Jacobian columns of the state, the offset and a drift),
    and whether the pass wants a drift it does not have (the GLS estimate of a drift, with the
    a-priori, beyond :data:`DRIFT_T` sigmas; only under ``noise="auto"`` without ``doppler_bias``).
    Returns ``(the Refinement with the model, drift wanted)``; the model is reported in
    ``noise_report``."""
    opt = ref.options
    meas = ref.problem.meas
    keep = ~np.asarray(sol.edited, bool)
    t = meas.t_s
    t0 = float(t.min())
    wander = ref.oscillator_wander()        # its walk: given (--oscillator-noise) or None (by REML)
    osc = wander is not None
    r = np.asarray(sol.residual, float)
    npb = ref.n_problem
    _, jac = ref.pointwise_model(sol.values)
    x = np.asarray(jac, float)[:, :npb]
    has_drift = bool(ref.modifier_drivers(md.DopplerDrift))
    if osc and not has_drift:        # the drift column (Hz/s; the offset's column times t - t0)
        i_off = ref.problem.names.index(ref.modifier_drivers(md.DopplerOffset)[0].name)
        x = np.column_stack([x, x[:, i_off] * (t - t0)])
    nf = nz.fit_noise(t[keep], r[keep], x[keep], models=nz.candidate_models(opt.noise, osc),
                      walk=wander.walk if wander is not None else opt.oscillator_noise, t0=t0)
    cov = nz.PassCovariance(meas.sigma, t, [(np.arange(t.size), nf.model, t0)])
    want_drift = False
    drift_t = None
    if osc and not has_drift:
        w = cov.whitener(keep)
        a = w(x)
        b = w(r)
        pa, factors = prior_rows(ref.priors, len(ref.names), np.ones(len(ref.names)))
        if pa.shape[0]:
            pa = np.column_stack([pa[:, :npb], np.zeros(pa.shape[0])])
            a = np.vstack([a, pa])
            b = np.concatenate([b, prior_rhs(factors, np.asarray(sol.values, float))])
        u, sv, vt = np.linalg.svd(a, full_matrices=False)
        ok = sv > 1e-10 * sv[0]
        beta = vt[ok].T @ ((u[:, ok].T @ b) / sv[ok])
        sd = float(np.sqrt(np.sum((vt[ok, -1] / sv[ok]) ** 2)))
        drift_t = float(beta[-1] / sd) if sd > 0 else 0.0
        want_drift = (opt.noise == "auto" and opt.doppler_bias is None
                      and abs(drift_t) > max(DRIFT_T, math.sqrt(math.log(max(keep.sum(), 3)))))
    report = nf.as_dict()
    report.update({"option": opt.noise,
                   "oscillator_noise_given": opt.oscillator_noise, "link": link_mode(ref)})
    if drift_t is not None:
        report["drift_t"] = drift_t
    bias = ref.modifier_drivers(md.DopplerOffset, md.DopplerDrift)
    report["transmitter"] = ("offset+drift" if (want_drift or has_drift) else "offset" if bias else "none") + \
        ("+wander" if nf.model.walk > 0 else "")
    model = None if nf.model.is_white else cov
    return replace(ref, noise=model, noise_edited=np.asarray(sol.edited, bool).copy(), noise_report=report), want_drift


def solve_noise(table, initial, ref: Refinement, stations=None, eop=None, source: str = "<pass>", rounds: int = 1,
                observed=None, prior_centre=None, x0=None):
    """:func:`solve_weighted` with the noise model of the pass (:func:`noise_model`): a first
    (white) fit, the model by REML, a drift if the pass wants one (the problem prepared again
    from ``table``/``initial`` with ``offset+drift``), then GLS; with ``rounds`` > 1 the model is
    refitted on the GLS residuals and the fit repeated (REML does not depend on the fixed
    effects' estimate to first order: a second round changed the DopTrack development ratios by
    < 0.01 and costs 0.1 s of CPU, so one is the default). A pass whose noise is white and needs no drift keeps the
    white fit unchanged. ``observed``, ``prior_centre``, ``x0`` as in :meth:`Refinement.solve`
    (Monte Carlo: the problem must then already carry the drift it needs).
    Returns ``(Refinement, Solution, KKTResult or None, sigma scale)``."""
    sol, kkt, scale = solve_weighted(ref, observed, prior_centre, x0)
    if ref.options.cost != "pointwise" or (ref.options.noise == "white" and ref.options.oscillator_noise is None):
        return ref, sol, kkt, scale
    for _ in range(rounds):
        noisy, want_drift = noise_model(ref, sol, scale)
        if want_drift and observed is None:
            ref = prepare(table, initial, stations, replace(ref.options, doppler_bias="offset+drift"), eop, source,
                          curve=ref.curve, like=ref)   # the same smoothed curve and epoch: no second smoothing
            noisy = replace(ref, noise=noisy.noise, noise_edited=noisy.noise_edited, noise_report=noisy.noise_report)
        elif not noisy.correlated() and not ref.correlated():
            return noisy, sol, kkt, scale                 # white, no drift to add: the white fit stands
        start = x0 if x0 is not None else warm_start(ref, noisy, sol)
        ref = noisy
        sol, kkt, scale = solve_weighted(ref, observed, prior_centre, start)
    return ref, sol, kkt, scale


def warm_start(before: Refinement, after: Refinement, sol) -> np.ndarray:
    """The GLS solve's start: the white fit ``sol`` of ``before`` (the noise model moves the
    solution by a fraction of its sigma, so Gauss-Newton from there needs fewer evaluations than
    from the stale state), a parameter ``after`` adds (the drift) at its own start value."""
    old = dict(zip(before.names, np.asarray(sol.values, float)))
    return np.array([old.get(n, v) for n, v in zip(after.names, np.asarray(after.x0, float))])
