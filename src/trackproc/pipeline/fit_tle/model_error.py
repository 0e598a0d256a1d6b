"""SGP4's theory error as a per-pass random effect on the elements (step 7 of
:mod:`trackproc.pipeline.fit_tle`)."""

from __future__ import annotations

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.methods import tle_fit as tf
from trackproc.methods import tle_theory_error as te


def model_error_fit(options, sol, model, free, steps, obs, design, keep, sigma_eff, apriori_sigmas, prior, observed):
    """SGP4's theory error at each station pass (:func:`trackproc.methods.tle_theory_error.model_error_covariance`,
    ``options.model_error`` a-priori sigmas), a random effect: the elements by generalised least
    squares that weigh each pass by it (Gauss-Newton steps of
    :func:`~trackproc.methods.tle_theory_error.mixed_model_step` from the least-squares solution, the
    nuisance terms refitted at each), their estimation covariance, and the prediction covariance
    at a pass (that plus the pass's own theory error). Ephemeris rows carry none (a continuous
    arc, not passes). ``prior`` is ``(mean, covariance)`` or None."""
    scale = te.MODEL_ERROR_SCALE if options.model_error is None else float(options.model_error)
    q = te.model_error_covariance(scale, apriori_sigmas)
    idx = np.flatnonzero(free)
    m = idx.size
    q_free = q[np.ix_(idx, idx)]
    c_fit = sol.covariance[:m, :m]
    station = (obs["station"] != "").to_numpy()
    passes = (obs["source"].astype(str) + "|" + obs["pass_id"].astype(str)).to_numpy()
    groups = [np.flatnonzero((passes == p) & station) for p in sorted(set(passes[station]))]
    other = np.flatnonzero(~station)                 # ephemeris rows: no theory error
    w = np.where(keep, 1.0 / sigma_eff, 0.0)
    if prior is not None:
        p_info = np.linalg.inv(np.asarray(prior[1], float)[np.ix_(idx, idx)])
    else:
        p_info = np.zeros((m, m))
    x, c_est, n_pass = sol.x.copy(), c_fit, 0

    def data_terms(x):
        """Per pass the information and gradient of its samples (nuisance profiled out), and those
        of the other (ephemeris) rows, at ``x``."""
        r = observed - model(x)
        if design.shape[1]:
            r = r - design @ np.linalg.lstsq(design * w[:, None], r * w, rcond=None)[0]
        jac = tf.jacobian(model, x, free, steps)
        infos = [te.pass_information(jac[rows], w[rows], design[rows]) for rows in groups]
        grads = [jac[rows].T @ (w[rows] ** 2 * r[rows]) for rows in groups]
        o_info, o_grad = np.zeros((m, m)), np.zeros(m)
        if other.size:
            o_info = te.pass_information(jac[other], w[other], design[other])
            o_grad = jac[other].T @ (w[other] ** 2 * r[other])
        return infos, grads, o_info, o_grad

    if scale > 0 and groups:
        n_pass = len(groups)
        for _ in range(6):
            infos, grads, o_info, o_grad = data_terms(x)
            o_info = o_info + p_info
            if prior is not None:
                o_grad = o_grad + p_info @ ((np.asarray(prior[0], float) - x)[idx])
            step, c_est = te.mixed_model_step(np.zeros(m), c_fit, infos, grads, q_free, o_info, o_grad)
            for _ in range(8):              # halved while SGP4 refuses the elements (far from linear)
                trial = x.copy()
                trial[idx] += step
                try:
                    model(trial)
                    break
                except (ValueError, ArithmeticError, ProcessingError):
                    step = step / 2.0
            else:
                break
            x = trial
            if np.max(np.abs(step) / np.sqrt(np.diag(c_est))) < 0.01:
                break

    # the a-priori conflict test under the same error model (theory error included): the data's
    # information and gradient at the final elements (one more Jacobian), linearised to x_p
    conflict = None
    if prior is not None:
        infos, grads, o_info, o_grad = data_terms(x)
        a_data, g_data = te.deflated_normal(infos, grads, q_free if scale > 0 else np.zeros((m, m)), o_info, o_grad)
        score = g_data + a_data @ (x - np.asarray(prior[0], float))[idx]
        chi2, used = te.apriori_conflict_chi2(score, a_data, np.asarray(prior[1], float)[np.ix_(idx, idx)])
        conflict = {"chi2": chi2, "directions": used}

    def full(block):
        out = np.zeros((7, 7))
        out[np.ix_(idx, idx)] = block
        return out

    return {"scale": scale, "sigma": dict(zip(tf.ELEMENT_NAMES, np.sqrt(np.diag(q)).tolist())),
            "source": "--model-error" if options.model_error is not None else
            "default: calibrated on the DopTrack Delfi-C3 development evenings (docs/fit-tle.md)",
            "passes_with_it": n_pass, "element_covariance": q,
            "estimation_covariance": full(c_est), "covariance_without_model_error": full(c_fit),
            "prediction_covariance": full(c_est) + q, "x": x, "apriori_conflict": conflict}
