"""Consistency gates of a solution: the statistics and the machine-readable ``quality`` verdict.

Pure functions on what any least-squares solver gives (residuals, a-priori share of chi2,
covariance), so they hold whatever noise model produced the residuals:

* :func:`prior_variance_component` — the maximum-likelihood (Helmert/Förstner) variance
  component of the a-priori block: how much the a-priori covariance must be scaled for the
  data to agree with it.
* :func:`lag1_autocorrelation`, :func:`runs_test`, :func:`effective_samples` — whiteness of
  the normalised residuals and the number of independent samples they are worth.
* :class:`Quality` — the verdict ``ok`` / ``suspect`` / ``rejected`` with its reasons, each
  ``{"code", "message", "value", "limit", "severity"}``; the worst reason decides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

VERDICTS = ("ok", "suspect", "rejected")
#: Significance of the chi-square gates (a-priori conflict, variance factor): 99.9 %.
GATE_PROBABILITY = 0.999
#: Lag-1 autocorrelation of the normalised residuals above which they are not white.
WHITENESS_RHO = 0.3
#: The runs test's |z| above which the residual signs are not random.
RUNS_Z = 3.29


@dataclass
class Quality:
    """The verdict and its reasons (the worst reason's severity is the verdict)."""

    reasons: list = field(default_factory=list)

    def add(self, code: str, severity: str, message: str, value=None, limit=None) -> None:
        if severity not in VERDICTS:
            raise ValueError(f"unknown severity {severity!r}")
        self.reasons.append({"code": code, "severity": severity, "message": message,
                             "value": _plain(value), "limit": _plain(limit)})

    @property
    def verdict(self) -> str:
        worst = 0
        for r in self.reasons:
            worst = max(worst, VERDICTS.index(r["severity"]))
        return VERDICTS[worst]

    def as_dict(self) -> dict:
        return {"verdict": self.verdict, "reasons": [dict(r) for r in self.reasons]}

    def text(self) -> str:
        """One line for stderr: ``quality: suspect (low_pass, whiteness)``."""
        bad = [r["code"] for r in self.reasons if r["severity"] != "ok"]
        return f"quality: {self.verdict}" + (f" ({', '.join(bad)})" if bad else "")


def _plain(v):
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(a) for a in np.asarray(v).tolist()]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    f = float(v)
    return f if math.isfinite(f) else None


def chi2_limit(dof: int, probability: float = GATE_PROBABILITY) -> float:
    """The ``probability`` quantile of χ²(dof)."""
    from scipy.special import gammaincinv  # chi-square quantile without scipy.stats (issue 19)

    return 2.0 * float(gammaincinv(max(int(dof), 1) / 2.0, probability))


def add_apriori_check(q, chi2: float, rows: int, noun: str, conflict: str) -> None:
    """Reason ``apriori_conflict`` of a solution that kept its a-priori: ``ok`` when its share of
    χ² is within the 99.9 % point of χ²(rows), ``rejected`` (with ``conflict`` saying why the
    covariance then fails) beyond it."""
    limit = chi2_limit(rows)
    ok = chi2 <= limit
    q.add("apriori_conflict", "ok" if ok else "rejected",
          f"a-priori chi2 {chi2:.4g} over {rows} {noun} (99.9 % limit {limit:.3g})" + ("" if ok else ": " + conflict),
          value=chi2, limit=limit)


def variance_factor_limit(dof: int, probability: float = GATE_PROBABILITY) -> float:
    """Upper ``probability`` quantile of the variance factor χ²(dof)/dof of a consistent fit."""
    return chi2_limit(dof, probability) / max(int(dof), 1)


def prior_redundancy(posterior_cov_block: np.ndarray, prior_cov: np.ndarray) -> float:
    """Redundancy number of an a-priori block on parameters directly: ``n - tr(C_post P)``, with
    ``C_post`` the posterior covariance of those parameters and ``P`` the a-priori weight
    (Förstner 1979; Koch, Parameter Estimation and Hypothesis Testing, 1999, eq. 3.287 with an
    identity design). It is the part of the a-priori rows the data can check: 0 when the data
    see nothing of it, ``n`` when they fix it alone."""
    c = np.asarray(posterior_cov_block, float)
    p = np.linalg.inv(np.asarray(prior_cov, float))
    return float(c.shape[0] - np.trace(c @ p))


def prior_variance_component(chi2_prior: float, redundancy: float) -> Optional[float]:
    """Helmert/Förstner estimate of the a-priori block's variance component,
    ``σ²_p = vᵀ P v / r_p`` (Koch 1999, eq. 3.291): the factor by which the a-priori covariance
    must be scaled for its share of χ² to equal its redundancy. None when the data cannot check
    the a-priori (redundancy below 0.05)."""
    if not (redundancy > 0.05) or not math.isfinite(chi2_prior):
        return None
    return float(chi2_prior / redundancy)


def lag1_autocorrelation(x) -> float:
    """Lag-1 autocorrelation of a series (mean removed); NaN for fewer than 3 values."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size < 3:
        return math.nan
    x = x - x.mean()
    den = float(x @ x)
    return float(x[:-1] @ x[1:] / den) if den > 0 else math.nan


def runs_test(x) -> float:
    """Wald–Wolfowitz runs test of the signs of ``x`` about its median: the normal score ``z``
    of the number of runs (Wald & Wolfowitz 1940); strongly negative when the residuals come in
    long runs of one sign (a systematic error), NaN for fewer than 10 values."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    s = x > np.median(x)
    n1, n2 = int(s.sum()), int((~s).sum())
    n = n1 + n2
    if n < 10 or n1 == 0 or n2 == 0:
        return math.nan
    runs = 1 + int(np.count_nonzero(s[1:] != s[:-1]))
    mean = 2.0 * n1 * n2 / n + 1.0
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1.0))
    return float((runs - mean) / math.sqrt(var)) if var > 0 else math.nan


def effective_samples(n: int, rho: float) -> float:
    """Independent samples an AR(1) series of ``n`` with lag-1 correlation ``rho`` is worth for
    its mean: ``n (1 - ρ)/(1 + ρ)`` (e.g. von Storch & Zwiers 1999, eq. 6.13); ``n`` for ρ <= 0."""
    if not math.isfinite(rho) or rho <= 0:
        return float(n)
    rho = min(rho, 0.999)
    return float(max(1.0, n * (1.0 - rho) / (1.0 + rho)))


def whiteness(normalized) -> dict:
    """Lag-1 autocorrelation, runs-test z and effective sample count of normalised residuals."""
    r = np.asarray(normalized, float)
    r = r[np.isfinite(r)]
    rho = lag1_autocorrelation(r)
    return {"n": int(r.size), "lag1_autocorrelation": rho, "runs_z": runs_test(r),
            "effective_samples": effective_samples(r.size, rho)}


def add_whiteness(q: Quality, w: dict) -> None:
    """The residual-whiteness reason (``suspect`` when lag-1 ρ > :data:`WHITENESS_RHO` or the
    runs test rejects at |z| > :data:`RUNS_Z`)."""
    rho, z = w["lag1_autocorrelation"], w["runs_z"]
    if not math.isfinite(rho):
        return
    bad = rho > WHITENESS_RHO or (math.isfinite(z) and abs(z) > RUNS_Z)
    q.add("whiteness", "suspect" if bad else "ok",
          (f"the residuals are correlated in time (lag-1 autocorrelation {rho:.2f}, runs-test z {z:.1f}; worth "
           f"{w['effective_samples']:.0f} independent samples of {w['n']}): a covariance that assumes white noise "
           "is optimistic") if bad else
          f"residuals white enough (lag-1 autocorrelation {rho:.2f}, runs-test z {z:.1f})",
          value=rho, limit=WHITENESS_RHO)


def correlation_inflation(rho: float) -> float:
    """Factor by which white-noise information overstates that of an AR(1) series with lag-1
    correlation ``rho``: ``(1 + ρ)/(1 - ρ)`` (the inverse of :func:`effective_samples`' ratio);
    1 for ρ <= 0."""
    if not math.isfinite(rho) or rho <= 0:
        return 1.0
    rho = min(rho, 0.999)
    return float((1.0 + rho) / (1.0 - rho))


def improvement_test(chi2_stale: float, chi2_refined: float, dof: int, inflation: float = 1.0,
                     probability: float = GATE_PROBABILITY) -> dict:
    """Does the pass need the correction? The likelihood-ratio statistic of the stale state
    (nuisance parameters refitted) against the refined one, ``Δχ² = χ²(stale) - χ²(refined)``,
    is χ²(``dof``) when the stale state is right; time-correlated residuals make it ``inflation``
    times too large (:func:`correlation_inflation`), so ``Δχ²/inflation`` is compared with the
    ``probability`` point. ``significant`` False: the data cannot tell the refined state from
    the stale one."""
    delta = float(chi2_stale - chi2_refined)
    eff = delta / max(float(inflation), 1.0)
    limit = chi2_limit(dof, probability)
    return {"delta_chi2": delta, "inflation": float(inflation), "delta_chi2_effective": eff, "dof": int(dof),
            "limit": limit, "significant": bool(eff > limit)}


def block_consistency(jac_w, z, covariance, rows, tol: float = 1e-6) -> dict:
    """Does one block of samples (a pass) agree with the solution the others give? The score
    (Rao) statistic of the alternative "the block has its own copy of every parameter it is
    sensitive to" in the linearised whitened problem: with ``E`` the block's whitened Jacobian
    columns (zero outside the block), ``g = Eᵀ z`` and ``M = Eᵀ Q_vv E = AᵀA − AᵀJ_B C J_Bᵀ A``
    (``Q_vv = I − J C Jᵀ`` the residuals' cofactor matrix, ``C`` the posterior covariance with
    any a-priori), ``T = gᵀ M⁺ g`` is χ²(rank M) when the model holds (the test of added
    parameters in a Gauss-Markov model; Koch, Parameter Estimation and Hypothesis Testing, 1999,
    sec. 4.3; for one parameter per sample it is Baarda's data snooping). It is the χ² a block
    gains by being allowed its own state: large when one pass pulls the solution its own way (an
    oscillator step absorbed by the orbit, another satellite's pass) even when the pass then fits
    white. Directions the block alone determines (its own offsets; ``M``'s eigenvalues below
    ``tol`` of the column-normalised matrix) cannot be tested and are not counted.

    ``jac_w`` (N, n) whitened Jacobian of the kept samples, ``z`` (N,) whitened residuals,
    ``covariance`` (n, n), ``rows`` the block's indices. Returns ``{"statistic", "dof"}``."""
    jac_w = np.asarray(jac_w, float)
    jb = jac_w[np.asarray(rows, int)]
    cols = np.flatnonzero(np.any(jb != 0.0, axis=0))
    if cols.size == 0:
        return {"statistic": 0.0, "dof": 0}
    a = jb[:, cols]
    g = a.T @ np.asarray(z, float)[np.asarray(rows, int)]
    h = a.T @ jb                                           # AᵀJ_B
    m = a.T @ a - h @ np.asarray(covariance, float) @ h.T
    d = 1.0 / np.sqrt(np.maximum(np.diag(a.T @ a), 1e-300))
    lam, vec = np.linalg.eigh((m * d[:, None]) * d[None, :])
    keep = lam > tol * max(float(lam.max()), 0.0)
    if not keep.any():
        return {"statistic": 0.0, "dof": 0}
    proj = vec[:, keep].T @ (g * d)
    return {"statistic": float(np.sum(proj ** 2 / lam[keep])), "dof": int(keep.sum())}


def chi2_survival(x: float, dof: int) -> float:
    """P(χ²(dof) > x)."""
    from scipy.special import gammaincc  # start-up: scipy.special (~0.25 s) only when a test is evaluated

    return float(gammaincc(max(int(dof), 1) / 2.0, max(float(x), 0.0) / 2.0))


def whiteness_score(w: dict) -> float:
    """One pass's evidence of time correlation, in normal scores: the larger of the lag-1
    autocorrelation times ``√n`` (≈ N(0, 1) for white residuals; Box & Jenkins) and the runs
    test's ``|z|``."""
    rho, z = w["lag1_autocorrelation"], w["runs_z"]
    runs = abs(z) if math.isfinite(z) else 0.0
    return max(rho * math.sqrt(w["n"]) if math.isfinite(rho) else 0.0, runs)


def whiteness_family_limit(m: int, probability: float = GATE_PROBABILITY) -> float:
    """The normal score above which the worst of ``m`` passes' :func:`whiteness_score` is not
    chance at ``probability`` (Bonferroni over the m passes and the two tests:
    ``Φ⁻¹(1 - (1 - probability)/(2m))``)."""
    from scipy.special import ndtri  # start-up: as in chi2_survival

    return float(ndtri(1.0 - (1.0 - probability) / (2 * max(int(m), 1))))


def add_whiteness_family(q: Quality, passes: list) -> None:
    """The residual-whiteness reason over several passes (``[{"pass", "whiteness"}, ...]``):
    ``suspect`` when the worst pass's :func:`whiteness_score` is beyond
    :func:`whiteness_family_limit` (a false alarm on at most 0.1 % of white solutions, however
    many passes; the fixed ρ > :data:`WHITENESS_RHO` of :func:`add_whiteness` fires on the worst
    of twelve 22-sample white passes about one time in two), the worst pass named."""
    passes = [p for p in passes if math.isfinite(p["whiteness"]["lag1_autocorrelation"])]
    if not passes:
        return
    limit = whiteness_family_limit(len(passes))
    worst = max(passes, key=lambda p: whiteness_score(p["whiteness"]))
    w = worst["whiteness"]
    score = whiteness_score(w)
    bad = score > limit
    q.add("whiteness", "suspect" if bad else "ok",
          (f"pass {worst['pass']}: the residuals are correlated in time (lag-1 autocorrelation "
           f"{w['lag1_autocorrelation']:.2f} over {w['n']} samples, runs-test z {w['runs_z']:.1f}: score {score:.2f}, "
           f"limit {limit:.2f} for the worst of {len(passes)} passes; worth {w['effective_samples']:.0f} independent "
           "samples): a covariance that assumes white noise is optimistic") if bad else
          (f"residuals white enough (worst pass {worst['pass']}: lag-1 autocorrelation "
           f"{w['lag1_autocorrelation']:.2f} over {w['n']}, runs-test z {w['runs_z']:.1f}; score {score:.2f}, "
           f"limit {limit:.2f})"),
          value=w["lag1_autocorrelation"], limit=limit / math.sqrt(w["n"]))


def step_scan(jac_w, z, covariance, rows, weights, margin: int = 3, whiten=None) -> dict:
    """The largest score statistic of "a level shift from sample s on" in one block of white
    samples (time order), over every s with ``margin`` samples either side: the step column
    ``e_s = weights · 1[i ≥ s]`` (``weights`` = 1/σ of the block's samples, so that ``e_s`` is
    whitened like the rows) tested as :func:`block_consistency` tests a block's own parameters,
    ``T_s = (e_sᵀz)² / (e_sᵀe_s − u_sᵀ C u_s)``, ``u_s = J_Bᵀ e_s``: χ²(1) for each s when the
    model holds (Koch 1999 sec. 4.3). A frequency step of the transmitter inside a pass, a bias
    or time-tag jump: what the orbit, an offset and a drift can absorb is not counted, the rest
    is. ``weights`` may be any per-sample coefficient of the shift (the samples' partials of a
    time-tag jump, ``ḣ/σ``, scan for a jump of the time tags). With correlated samples ``whiten``
    maps the raw step columns (``weights · 1[i ≥ s]``, one per candidate s, rows in the order of
    ``rows``) to whitened ones like the rows (``L⁻¹``; ``weights`` then unwhitened coefficients).
    Returns ``{"statistic", "index" (position in ``rows``), "candidates", "estimate"}``, the
    estimate being the one-step size of the shift, ``e_sᵀz / (e_sᵀe_s − u_sᵀ C u_s)``, in the
    unit of the coefficients."""
    rows = np.asarray(rows, int)
    n = rows.size
    if n < 2 * margin + 1:
        return {"statistic": 0.0, "index": -1, "candidates": 0, "estimate": 0.0}
    jb = np.asarray(jac_w, float)[rows]
    w = np.asarray(weights, float)
    zb = np.asarray(z, float)[rows]
    s = np.arange(margin, n - margin + 1)
    cov = np.asarray(covariance, float)
    if whiten is None:
        # suffix sums: g_s = Σ_{i≥s} w_i z_i, ee_s = Σ w_i², u_s = Σ w_i J_B[i]
        g = np.cumsum((w * zb)[::-1])[::-1][s]
        ee = np.cumsum((w * w)[::-1])[::-1][s]
        u = np.cumsum((w[:, None] * jb)[::-1], axis=0)[::-1][s]
    else:
        e = whiten(w[:, None] * (np.arange(n)[:, None] >= s[None, :]))
        g, ee, u = e.T @ zb, np.einsum("ij,ij->j", e, e), e.T @ jb
    m = ee - np.einsum("ij,jk,ik->i", u, cov, u)
    ok = m > 1e-9 * ee
    if not ok.any():
        return {"statistic": 0.0, "index": -1, "candidates": 0, "estimate": 0.0}
    t = np.where(ok, g ** 2 / np.where(ok, m, 1.0), 0.0)
    k = int(np.argmax(t))
    return {"statistic": float(t[k]), "index": int(s[k]), "candidates": int(ok.sum()), "estimate": float(g[k] / m[k])}


#: :func:`prior_innovation_chi2` uses the directions where the data's information is at least this
#: fraction of the a-priori's (posterior variance at most 1/(1 + floor) of the a-priori's). The
#: statistic is χ² with that many degrees of freedom whatever the floor; the floor only leaves out
#: the directions the pass barely sees, where it has no power (an a-priori error there must exceed
#: ``4/√floor`` a-priori sigmas to be seen) and where the linear statistic would rest on the
#: curvature of the cost (the rotation about the station axis).
PRIOR_INNOVATION_FLOOR = 0.1


def prior_innovation_chi2(delta, prior_cov, posterior_cov, floor: float = PRIOR_INNOVATION_FLOOR,
                          consider_cov=None) -> tuple:
    """Do the data contradict an a-priori ``x_p ~ N(x_true, P)``? The innovation of the a-priori,
    ``T = δᵀ (P − C)⁺ δ`` with ``δ = x̂ − x_p`` the correction made by a (generalised)
    least-squares solution with the a-priori and ``C`` its covariance (nuisance parameters
    profiled: the state block of the full covariance), ``P − C`` being the covariance of ``δ``
    when the a-priori is right (Tapley, Schutz & Born 2004, section 4.4; the same statistic as
    :func:`trackproc.methods.tle_theory_error.apriori_conflict_chi2`, written with the posterior
    instead of the data's information). Computed in the a-priori's whitened coordinates
    (``P = L Lᵀ``, ``L⁻¹ C L⁻ᵀ = V diag(c) Vᵀ``, the data's information ``λ = 1/c − 1``,
    ``u = Vᵀ L⁻¹ δ``): ``T = Σ u² (1 + λ)/λ`` over the directions with ``λ >= floor``, χ² with
    that many degrees of freedom under the a-priori. Unlike the a-priori's share of the cost
    ``δᵀ P⁻¹ δ`` (distributed as ``Σ λ/(1+λ) χ²₁``, mean the redundancy, tested against χ²(6)),
    it keeps its power where the pass is weak against the a-priori (a low, short or noisy pass; a
    wandering oscillator). ``consider_cov`` (``E``): the covariance an error the solution does not
    estimate adds to it (a consider parameter, e.g. a station's time-tag offset; Tapley, Schutz &
    Born 2004, section 6.3): ``δ`` then has covariance ``P − C + E``, and ``T = δᵀ (P − C + E)⁻¹ δ``
    over the same directions. Returns ``(T, degrees of freedom)``."""
    p = np.asarray(prior_cov, float)
    low = np.linalg.cholesky(0.5 * (p + p.T))
    li = np.linalg.inv(low)
    cw = li @ np.asarray(posterior_cov, float) @ li.T
    c, vec = np.linalg.eigh(0.5 * (cw + cw.T))
    c = np.clip(c, 1e-300, None)
    lam = 1.0 / c - 1.0
    u = vec.T @ (li @ np.asarray(delta, float))
    use = lam >= floor
    if consider_cov is None:
        return float(np.sum(u[use] ** 2 * (1.0 + lam[use]) / lam[use])), int(use.sum())
    # (1 + λ)/λ = 1/(1 − c): P − C is diag(1 − c) in these coordinates; E is added there
    vs = vec[:, use]
    m = np.diag(1.0 - c[use]) + vs.T @ li @ np.asarray(consider_cov, float) @ li.T @ vs
    return float(u[use] @ np.linalg.solve(0.5 * (m + m.T), u[use])), int(use.sum())


def apriori_conflict(chi2: float, rows: int, delta=None, prior_cov=None, posterior_cov=None, consider_cov=None) -> dict:
    """Do the data contradict a state a-priori? :func:`prior_innovation_chi2` of the correction
    ``delta`` when the full a-priori and posterior covariances are given (it keeps its power when
    the data are weak against the a-priori), else the a-priori's share of χ² ``chi2`` over its
    ``rows`` against χ²(rows); at 99.9 %. Returns ``{"chi2", "rows" (the share), "statistic",
    "dof", "limit", "conflict", "test"}`` (refine's and estimate's a-priori gate)."""
    out = {"chi2": chi2, "rows": rows, "statistic": chi2, "dof": rows, "test": "a-priori share of chi2"}
    if delta is not None and prior_cov is not None and posterior_cov is not None:
        try:
            stat, dof = prior_innovation_chi2(delta, prior_cov, posterior_cov, consider_cov=consider_cov)
            out.update(statistic=stat, dof=dof, test="innovation of the a-priori")
        except np.linalg.LinAlgError:
            pass
    out["limit"] = chi2_limit(out["dof"])
    out["conflict"] = bool(out["dof"] > 0 and out["statistic"] > out["limit"])
    return out
