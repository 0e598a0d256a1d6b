"""Measurement noise that is not white: an oscillator that wanders and time-correlated noise.

A one-way Doppler link measures the received frequency against an onboard oscillator whose
frequency is not a constant: beside an offset and a drift (explicit parameters of the
estimator) it wanders (temperature, ageing), and the residuals of a real pass are correlated
from sample to sample. Weighing such samples as independent makes the covariance far too small
and lets the orbit absorb the wander. The covariance of the samples of one pass (times ``t``,
``t0`` the first one, which is also the epoch of the explicit offset and drift) is modelled as

    C_ij = σ_w² δ_ij  +  σ_a² exp(-|t_i - t_j| / τ)  +  q² min(t_i - t0, t_j - t0)

* white noise ``σ_w`` (2 Hz quantisation alone is 2/√12 = 0.58 Hz);
* a first-order Gauss-Markov (exponentially correlated, AR(1) on a regular grid with
  ``ρ = exp(-Δt/τ)``) component ``σ_a, τ``: uneven sampling and gaps need nothing special;
* a random walk of the transmitter frequency of intensity ``q`` (unit/√s): the covariance of
  a Wiener process started at ``t0`` (its initial value is the explicit offset).

This dense per-pass form is the batch form of "frequency nodes with a random-walk prior between
them" with the nodes marginalised out (a Kalman smoother would give the same estimate and
covariance): generalised least squares with ``C`` (Aitken 1935) by whitening with the Cholesky
factor, ``C = L Lᵀ``: residuals and Jacobian rows become ``L⁻¹ r``, ``L⁻¹ J``
(:class:`~trackproc.methods.whitening.PassCovariance`, re-exported here).

The hyper-parameters are estimated by restricted maximum likelihood (REML; Patterson &
Thompson 1971, Harville 1977) on the residuals of a first fit, the fixed effects being the
columns of the estimator's design for the pass (state, offset, drift), so that what the orbit
or the offset can absorb is not taken for noise:

    ℓ_R(θ) = -½ [ log|C| + log|Xᵀ C⁻¹ X| + rᵀ P r ],   P = C⁻¹ - C⁻¹X(XᵀC⁻¹X)⁻¹XᵀC⁻¹

with the overall scale profiled out (``σ̂² = rᵀ P̃ r / (n - p)``). The model (white, + AR(1),
+ random walk, + both) is chosen per pass by the restricted likelihood with a penalty: a
component is added only when twice the log-likelihood gain exceeds both the BIC penalty
(Schwarz 1978: ``k ln n``) and the 99.9 % point of χ² with its number of parameters, so that
white noise stays white (the white path is then exactly the weighted least squares of before);
among the correlated models that pass this test, the most general. An AR(1) of a time constant
much longer than the pass and a random walk are nearly the same process once the offset is
estimated, and at short lags a walk plus white noise
resembles an AR(1): one pass rarely tells them apart, and the model that carries both keeps the
covariance honest whichever it is.

For speed the likelihood is evaluated on at most :data:`MAX_REML_SAMPLES` samples (runs of
consecutive samples spread over the pass: the exact restricted likelihood of that subset, which
keeps the shortest lags), the final fit uses every sample.

Pure numpy/scipy. One responsibility, the noise model of a pass (its candidates, likelihood, starts
and choice), ~450 lines with the likelihood's exact and compiled evaluations side by side; its
minimiser is :mod:`trackproc.methods.trust_region`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from typing import Optional, Sequence

import numpy as np

from trackproc.methods.distributions import chi2_quantile
from trackproc.methods.lapack import routines
from trackproc.methods.trust_region import minimise
from trackproc.methods.whitening import (MarkovFactor, PassCovariance, compiled_reml,  # noqa: F401  (re-exported)
                                        effective_samples, effective_samples_beyond, kept_markov_factor, markov_grid)

dgeqrf, = routines("dgeqrf")

__all__ = ["NoiseModel", "NoiseFit", "PassCovariance", "fit_noise", "restricted_loglik", "MODELS",
           "effective_samples", "effective_samples_beyond", "lag1_correlation", "candidate_models"]

#: Models, by the components they add to white noise.
MODELS = ("white", "ar1", "walk", "ar1+walk")
#: Samples the restricted likelihood is evaluated on (a subset of runs when the pass has more).
MAX_REML_SAMPLES = 320
#: Length of the runs of consecutive samples of the subset.
RUN_LENGTH = 4
#: A component is added when 2 Δℓ_R exceeds the χ² point of this probability (and BIC).
SELECTION_P = 0.999


@dataclass(frozen=True)
class NoiseModel:
    """The covariance of one pass's samples (see the module docstring): white ``white``,
    exponentially correlated ``ar_sigma`` with time constant ``ar_tau_s``, random walk
    ``walk`` (unit/√s). Units are the samples' (Hz for Doppler)."""

    white: float
    ar_sigma: float = 0.0
    ar_tau_s: float = 0.0
    walk: float = 0.0

    @property
    def name(self) -> str:
        parts = (["ar1"] if self.ar_sigma > 0 and self.ar_tau_s > 0 else []) + (["walk"] if self.walk > 0 else [])
        return "+".join(parts) or "white"

    @property
    def is_white(self) -> bool:
        return self.name == "white"

    def covariance(self, t_s, t0: Optional[float] = None) -> np.ndarray:
        """``C`` at the times ``t_s`` (s); the random walk starts at ``t0`` (default the first time)."""
        t = np.asarray(t_s, float)
        t0 = float(t.min()) if t0 is None else float(t0)
        c = np.diag(np.full(t.size, self.white ** 2))
        if self.ar_sigma > 0 and self.ar_tau_s > 0:
            c += self.ar_sigma ** 2 * np.exp(-np.abs(t[:, None] - t[None, :]) / self.ar_tau_s)
        if self.walk > 0:
            dt = np.clip(t - t0, 0.0, None)
            c += self.walk ** 2 * np.minimum(dt[:, None], dt[None, :])
        return c

    def as_dict(self) -> dict:
        return {"model": self.name, "white": self.white, "ar1_sigma": self.ar_sigma, "ar1_tau_s": self.ar_tau_s,
                "ar1_rho_1s": math.exp(-1.0 / self.ar_tau_s) if self.ar_sigma > 0 and self.ar_tau_s > 0 else 0.0,
                "walk_per_sqrt_s": self.walk}


def lag1_correlation(t_s, r, max_gap_s: Optional[float] = None) -> float:
    """Sample correlation of consecutive residuals (pairs closer than ``max_gap_s``, default
    twice the median step)."""
    t = np.asarray(t_s, float)
    r = np.asarray(r, float) - np.mean(r)
    if r.size < 3:
        return math.nan
    dt = np.diff(t)
    gap = 2.0 * float(np.median(dt)) if max_gap_s is None else max_gap_s
    ok = dt <= gap
    if ok.sum() < 2:
        return math.nan
    return float(np.sum(r[:-1][ok] * r[1:][ok]) / np.sum(r * r) * r.size / ok.sum())


# ----------------------------------------------------------------------------- REML

def _basis(x: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the column space of the fixed effects (REML depends on nothing else)."""
    x = np.asarray(x, float)
    if x.shape[1] == 0:
        return x
    norms = np.linalg.norm(x, axis=0)
    x = x[:, norms > 0] / norms[norms > 0]
    u, s, _ = np.linalg.svd(x, full_matrices=False)
    return u[:, s > 1e-9 * s[0]] if s.size else u


class _Reml:
    """The restricted likelihood of one set of residuals. The covariance is whitened in O(n)
    when the times are in order (:class:`~trackproc.methods.whitening.MarkovFactor`: the same
    Cholesky whitening as the dense factor, to rounding); ``dense=True`` (or unordered times)
    factorises the n x n covariance, with the time-difference matrices computed once (the test
    oracle of the O(n) path)."""

    def __init__(self, t, r, x, t0, dense: bool = False):
        self.t, self.r, self.x, self.t0 = t, r, x, t0
        self.n, self.p = x.shape
        self.dense = dense or (t.size > 1 and not np.all(np.diff(t) >= 0))
        self.xr = np.column_stack([x, r])        # the residuals last: see __call__
        self.grid = None if self.dense else markov_grid(t, t0)      # shared by every model evaluated
        self.kernel = None if self.dense else compiled_reml()       # looked up once per set of residuals
        self.xr_rows = np.ascontiguousarray(self.xr) if self.kernel is not None else None   # the kernel's layout
        if self.dense:
            self.lag = np.abs(t[:, None] - t[None, :])
            dt = np.clip(t - t0, 0.0, None)
            self.walk = np.minimum(dt[:, None], dt[None, :])

    def covariance(self, model: NoiseModel) -> np.ndarray:
        if not self.dense:
            return model.covariance(self.t, self.t0)
        c = model.white ** 2 * np.eye(self.n)
        if model.ar_sigma > 0 and model.ar_tau_s > 0:
            c += model.ar_sigma ** 2 * np.exp(-self.lag / model.ar_tau_s)
        if model.walk > 0:
            c += model.walk ** 2 * self.walk
        return c

    def _whitened(self, model: NoiseModel):
        """``(log|C|, L⁻¹ [X r])``, or None when ``C`` is not positive definite."""
        try:
            if self.dense:
                # start-up: scipy.linalg (~70 ms) only for times out of order (methods/lapack.py)
                from scipy.linalg import cho_factor, solve_triangular

                chol, _ = cho_factor(self.covariance(model), lower=True, check_finite=False)
                return (2.0 * float(np.sum(np.log(np.diag(chol)))),
                        solve_triangular(chol, self.xr, lower=True, check_finite=False))
            fac = kept_markov_factor(model, self.t, self.t0, self.grid)
        except np.linalg.LinAlgError:
            return None
        w = fac.whiten(self.xr)
        if not (math.isfinite(fac.logdet) and np.all(np.isfinite(w))):
            return None
        return fac.logdet, w

    def __call__(self, model: NoiseModel, profile: bool = True) -> tuple[float, float]:
        """``(ℓ_R, ŝ)``: see :func:`restricted_loglik`; ``profile=False``: the scale is 1."""
        n, p = self.n, self.p
        m = n - p
        got = self._whitened(model) if m > 0 else None
        if got is None:
            return -math.inf, math.nan
        logdet_c, w = got
        # One Householder QR of the whitened [X r] (LAPACK dgeqrf, R only; Golub & Van Loan 2013,
        # sec. 5.3.5): R's first p diagonal entries are those of X's own QR (|XᵀC⁻¹X| = Π R_ii²)
        # and its last one is the norm of r's part orthogonal to X (rᵀ P r = R_pp²). No Q is
        # formed: a third of the cost of numpy's qr and Q Qᵀ r on a pass's few hundred samples.
        qr, _, _, info = dgeqrf(w, overwrite_a=1)
        if info != 0:
            return -math.inf, math.nan
        d = np.abs(qr.diagonal())
        rss = float(d[p]) ** 2
        if not rss > 0:
            return -math.inf, math.nan
        logdet = logdet_c + 2.0 * float(np.log(d[:p]).sum())
        if not profile:
            return -0.5 * (logdet + rss), 1.0
        s2 = rss / m
        return -0.5 * (m * math.log(s2) + logdet + m), math.sqrt(s2)

    def fast(self, model: NoiseModel, profile: bool = True) -> float:
        """``ℓ_R`` of :meth:`__call__` by one compiled pass (:func:`~trackproc.methods.whitening.compiled_reml`:
        the filter's innovations rotated into R row by row, no factor object, no whitened copy), equal
        to it to rounding; :meth:`__call__` itself without the compiled kernel or for unordered times."""
        if self.kernel is None:
            return self(model, profile)[0]
        return self.fast_terms(model.white, model.ar_sigma, model.ar_tau_s, model.walk, profile)

    def fast_terms(self, white, ar_sigma, ar_tau_s, walk, profile: bool = True) -> float:
        """:meth:`fast` of ``NoiseModel(white, ar_sigma, ar_tau_s, walk)`` given by its four numbers
        (the search's points: no model object for each); needs the compiled kernel."""
        kernel = self.kernel
        n, p = self.n, self.p
        m = n - p
        if m <= 0:
            return -math.inf
        has_ar = ar_sigma > 0 and ar_tau_s > 0
        logdet_c, logdet_x, rss = kernel(self.grid[0], self.grid[1], float(ar_tau_s) if has_ar else 0.0,
                                         float(ar_sigma) ** 2 if has_ar else 0.0, float(walk) ** 2,
                                         float(white) ** 2, self.xr_rows, p)
        if not (math.isfinite(logdet_c) and rss > 0 and math.isfinite(rss)):
            return -math.inf
        logdet = logdet_c + logdet_x
        if not profile:
            return -0.5 * (logdet + rss)
        return -0.5 * (m * math.log(rss / m) + logdet + m)


def restricted_loglik(model, t, r, x, t0=None, profile: bool = True, dense: bool = False) -> tuple[float, float]:
    """Restricted log-likelihood (module docstring; the constant ``-½(n-p) log 2π`` left out) of
    residuals ``r`` at times ``t`` with fixed-effect columns ``x`` (an orthonormal basis, see
    :func:`_basis`) and the covariance ``s² C`` of the :class:`NoiseModel` ``model``, the scale
    ``s`` profiled out (``profile``; else ``s = 1``); in O(n) for times in order (``dense``: by
    the n x n Cholesky factor). Returns ``(ℓ_R, ŝ)``.
    Implements REML (Patterson & Thompson 1971; Harville 1977)."""
    t = np.asarray(t, float)
    return _Reml(t, np.asarray(r, float), np.asarray(x, float), float(t.min()) if t0 is None else t0,
                 dense)(model, profile)


def _subset(t: np.ndarray, max_n: int = MAX_REML_SAMPLES, run: int = RUN_LENGTH) -> np.ndarray:
    """Indices of runs of ``run`` consecutive samples spread evenly over the pass (all when few)."""
    n = t.size
    if n <= max_n:
        return np.arange(n)
    starts = np.unique(np.linspace(0, n - run, max_n // run).round().astype(int))
    return np.unique((starts[:, None] + np.arange(run)[None, :]).ravel())


@dataclass
class NoiseFit:
    """The chosen :class:`NoiseModel` of one pass and the evidence: restricted log-likelihood
    of each candidate (``candidates``: name -> dict), the samples used, the lag-1 correlation of
    the residuals, the effective number of independent samples under the chosen model
    (:func:`effective_samples_beyond`)."""

    model: NoiseModel
    candidates: dict
    n: int
    n_reml: int
    lag1: float
    n_effective: float
    how: str
    notes: list = field(default_factory=list)

    def as_dict(self) -> dict:
        out = self.model.as_dict()
        out.update({"how": self.how, "samples": self.n, "samples_reml": self.n_reml, "lag1_correlation": self.lag1,
                    "effective_samples": self.n_effective,
                    "effective_samples_definition": "(tr C')^2 / tr(C'^2), C' the noise covariance of the kept "
                                                    "samples without the explicit offset and drift (Bayley & "
                                                    "Hammersley 1946): n for white noise",
                    "candidates": self.candidates})
        if self.notes:
            out["notes"] = list(self.notes)
        return out


def _exp(x: float) -> float:
    """``exp`` of a log-parameter, capped at exp(600)."""
    return math.exp(min(float(x), 600.0))


#: The search's stopping point: a step below this in every log-parameter, or a promised gain of
#: the restricted log-likelihood below ``_FTOL`` (the choice compares 2 Δℓ with thresholds ≥ 2.7).
_XTOL, _FTOL = 0.01, 5e-4


@functools.lru_cache(maxsize=64)
def _chi2_point(d: int, p: float) -> float:
    """:func:`chi2_quantile`, once per (d, p) a process (every pass asks for the same few)."""
    return chi2_quantile(d, p)


def candidate_models(noise: str, oscillator: bool) -> tuple:
    """The noise models REML chooses among for ``--noise NOISE``: ``auto`` = every model on a
    one-way link with a transmitter frequency (:data:`MODELS`), white or AR(1) otherwise (no
    oscillator to wander); any other value is that model alone."""
    if noise == "auto":
        return MODELS if oscillator else ("white", "ar1")
    return (noise,)


def _starts(has_ar: bool, has_walk: bool, given: bool, tau_lo: float, tau_hi: float, z_sig: float, sd: float,
            fitted: dict) -> tuple[list, list]:
    """``(starts, bounds)`` of one candidate's search in its log-parameters (:func:`fit_noise`'s
    ``build``; the starts set which local maximum the search finds): ``tau_lo``, ``tau_hi`` log τ's
    bounds, ``z_sig`` the log walk intensity whose variance over the pass equals the white noise's,
    ``sd`` the residuals' scale, ``fitted`` the candidates fitted so far (name -> (model, ℓ_R, k, z))."""
    starts = [[]]
    bounds: list = []
    # starts (the best one is searched from): a coarse grid in τ (the likelihood has local
    # maxima there) and in the AR(1)'s share; the walk about the intensity whose variance over
    # the pass equals the white noise's (below it the likelihood is flat: no walk)
    if has_ar:
        starts = [[za, tt] for tt in np.linspace(tau_lo, tau_hi, 4) for za in (-4.0, -1.5, 1.0)]
        bounds += [(-12.0, 12.0), (tau_lo, tau_hi)]
    if has_walk:
        starts = [z + [zq] for z in starts for zq in (z_sig - 3.0, z_sig, z_sig + 3.0)]
        bounds += [(-40.0, 20.0)]
    if given:
        starts = [z + [math.log(sd)] for z in starts]
        bounds += [(math.log(sd) - 20.0, math.log(sd) + 5.0)]
    if has_ar and has_walk and not given:     # from the nested fits: the AR(1) alone, the walk alone
        zf = {o: fitted[o][3] for o in ("ar1", "walk") if o in fitted}
        starts = [] if zf else starts
        if "ar1" in zf:
            starts += [[zf["ar1"][0], zf["ar1"][1], z_sig + o] for o in (-6.0, -3.0, 0.0)]
        if "walk" in zf:
            # an AR(1) of 3 % of the white noise at the longest τ: it and the offset and drift
            # are nearly one thing, the likelihood is flat along it and the search leaves it here
            starts.append([math.log(1e-3), tau_hi, zf["walk"][0]])
            starts.append([0.0, tau_lo, zf["walk"][0]])
    return starts, bounds


def _by_point(fn):
    """``fn`` remembering its value at each point ``z`` it was given (by the point's bytes)."""
    memo: dict = {}

    def at(z):
        key = np.asarray(z, float).tobytes()
        if key not in memo:
            memo[key] = fn(z)
        return memo[key]
    return at


def fit_noise(t_s, residual, design, *, models: Sequence[str] = MODELS, walk: Optional[float] = None,
              white_floor: float = 0.0, t0: Optional[float] = None, p_select: float = SELECTION_P,
              dense: bool = False) -> NoiseFit:
    """Estimate and choose the noise model of one pass by REML (module docstring).

    ``t_s`` (n,) times, ``residual`` (n,) residuals of a first fit, ``design`` (n, p) its
    fixed-effect columns (the Jacobian rows of the pass: state, offset, drift; only their column
    space matters), ``models`` the candidates, ``walk`` a given random-walk intensity
    (``--oscillator-noise``: then the walk is not estimated and every candidate carries it),
    ``white_floor`` a lower bound of ``σ_w`` (quantisation), ``t0`` the start of the walk,
    ``dense``: the likelihood by the n x n Cholesky factor instead of the O(n) whitening (the
    test oracle; same result to rounding).
    """
    t = np.asarray(t_s, float)
    r = np.asarray(residual, float)
    n = t.size
    t0 = float(t.min()) if t0 is None else float(t0)
    idx = _subset(t)
    ts, rs = t[idx], r[idx]
    xs = _basis(np.asarray(design, float)[idx])
    m = max(ts.size - xs.shape[1], 1)
    span = max(float(ts.max() - ts.min()), 1.0)
    step = max(float(np.median(np.diff(t))) if n > 1 else 1.0, 1e-3)
    tau_lo, tau_hi = math.log(0.5 * step), math.log(2.0 * span)
    z_sig = -math.log(span)

    reml = _Reml(ts, rs, xs, t0, dense)
    sd = max(float(np.std(rs)), 1e-12)
    cands: dict = {}
    fitted: dict = {}
    for name in models:
        has_ar = "ar1" in name
        has_walk = "walk" in name and walk is None
        given = walk is not None

        def terms(z, has_ar=has_ar, has_walk=has_walk, given=given) -> tuple:
            # z: log(σ_a/σ_w)², log τ (AR); log(q/σ_w)² (walk); log σ_w (when the walk is given)
            # (the search stays within the bounds; exp is capped so that a point far out is a poor
            # likelihood, not an OverflowError)
            w = _exp(z[-1]) if given else 1.0
            a = math.sqrt(_exp(z[0])) * w if has_ar else 0.0
            tau = _exp(z[1]) if has_ar else 0.0
            q = walk if given else (math.sqrt(_exp(z[2 if has_ar else 0])) if has_walk else 0.0)
            return w, a, tau, q or 0.0

        def build(z, terms=terms) -> NoiseModel:
            return NoiseModel(*terms(z))

        # each point once (the search starts at the best start, already evaluated; the scale is read
        # at the end point): the exact path (ℓ_R, ŝ) and the compiled one (-ℓ_R, equal to rounding,
        # for the search's gradients and steps: its end point is then evaluated exactly, so a path
        # that reaches the same point of the 0.001 grid gives the same numbers)
        evaluate = _by_point(lambda z, build=build, given=given: reml(build(z), profile=not given))
        if reml.kernel is not None:           # the search's points by their numbers, no model object each
            neg_fast = _by_point(lambda z, terms=terms, given=given: -reml.fast_terms(*terms(z), profile=not given))
        else:
            neg_fast = _by_point(lambda z, build=build, given=given: -reml.fast(build(z), profile=not given))

        def neg(z, evaluate=evaluate):
            return -evaluate(z)[0]

        starts, bounds = _starts(has_ar, has_walk, given, tau_lo, tau_hi, z_sig, sd, fitted)
        if not bounds:
            ll, s = reml(NoiseModel(1.0))
            nm, k = NoiseModel(s), 1
        else:
            z0 = min(starts, key=lambda z: neg_fast(np.asarray(z)))
            z, ll = minimise(neg_fast, z0, bounds, xtol=_XTOL, ftol=_FTOL, final=neg)
            nm = build(z)
            s = 1.0 if given else evaluate(z)[1]
            nm = NoiseModel(nm.white * s, nm.ar_sigma * s, nm.ar_tau_s, nm.walk * s if not given else nm.walk)
            k = len(z) + (0 if given else 1)
        if white_floor > 0 and nm.white < white_floor:
            nm = replace(nm, white=white_floor)
        fitted[name] = (nm, ll, k, z if bounds else None)
        cands[name] = {"loglik_restricted": ll, "parameters": k, **nm.as_dict()}

    # choice: a correlated model must beat the simplest candidate by 2 Δℓ_R > max(d ln m, χ²_p(d))
    # (BIC, and at least the χ² point, so that white noise stays white); among those that do,
    # the most general one (with both components when it passes: an AR(1) and a walk are hard
    # to tell apart on one pass, and taking the one for the other leaves the offset and drift
    # overconfident, checked by Monte Carlo in tests/pipeline/test_refine_noise.py)
    base = min(models, key=lambda name: fitted[name][2])
    _, ll_base, k_base, _ = fitted[base]
    passing = [base]
    for name in models:
        _, ll, k, _ = fitted[name]
        d = k - k_base
        if d > 0 and 2.0 * (ll - ll_base) > max(d * math.log(m), _chi2_point(d, p_select)):
            passing.append(name)
    chosen = base if len(passing) == 1 else max(passing[1:], key=lambda name: (fitted[name][2], fitted[name][1]))
    model = fitted[chosen][0]
    return NoiseFit(model=model, candidates=cands, n=n, n_reml=int(ts.size), lag1=lag1_correlation(t, r),
                    n_effective=effective_samples_beyond(model, t, t0),
                    how="REML" if walk is None else "REML, walk given")
