"""The filter with each pass's correlated measurement noise (``--noise auto``): the noise model
estimate chooses per pass (REML), in sequential form (the AR(1) part a Gauss–Markov state of the
pass, the white part the samples' noise), against estimate's GLS with the same models."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trackproc.io.eop import earth_orientation
from trackproc.io.passfile import read_pass_table
from trackproc.io.statefile import read_state
from trackproc.io.stations import read_stations
from trackproc.pipeline.estimate import EstimateOptions, build_problem
from trackproc.pipeline.estimate.gates import solve as estimate_solve
from trackproc.pipeline.filter import FilterOptions
from trackproc.pipeline.filter import run as fr
from trackproc.pipeline.filter.noise import pass_noise
from trackproc.pipeline.filter.result import filter_quality

DATA = Path(__file__).resolve().parents[2] / "sample_data"
#: the simulated AR(1) noise: steady-state sigma (m/s, four times the samples' white 5 mm/s) and
#: correlation per 10 s sample step (time constant tau = -10 s / ln(phi) = 60 s)
AR_SIGMA, PHI = 0.02, float(np.exp(-10.0 / 60.0))


@pytest.fixture(scope="module")
def case():
    eop, _ = earth_orientation(None, None)
    tables = [("multistation", read_pass_table(str(DATA / "multistation.parquet")))]
    truth = read_state(str(DATA / "truth_at_start.json"), eop)
    eo = EstimateOptions(apriori_sigma={"position": 100.0, "velocity": 0.1}, noise="auto", clip=None,
                         kinds=["range_rate"])
    pb = build_problem(tables, truth, read_stations(str(DATA / "stations.csv")), eo, eop)
    return eop, tables, truth, eo, pb.model(truth.rv)[0]


def _ar1(t, rng):
    """An AR(1) sequence of steady-state sigma AR_SIGMA at the times t of one pass (in order):
    x_k = phi^(dt/10) x_(k-1) + sqrt(1 - phi^(2 dt/10)) sigma w_k, the exact discretisation."""
    x = np.empty(t.size)
    x[0] = AR_SIGMA * rng.standard_normal()
    for k in range(1, t.size):
        e = PHI ** ((t[k] - t[k - 1]) / 10.0)
        x[k] = e * x[k - 1] + np.sqrt(1.0 - e * e) * AR_SIGMA * rng.standard_normal()
    return x


def _problem(case, seed):
    """Range-rate of the truth orbit at the multistation samples (14 passes, 743 samples, 10 s
    steps) plus white noise at their sigma and an AR(1) per pass; a first guess 100 m / 0.1 m/s
    off with that a-priori."""
    eop, tables, truth, eo, h0 = case
    pb = build_problem(tables, truth, read_stations(str(DATA / "stations.csv")), eo, eop)
    rng = np.random.default_rng(seed)
    meas = pb.meas
    y = h0 + meas.sigma * rng.standard_normal(h0.size)
    for pid in np.unique(meas.pass_id):
        rows = np.flatnonzero(meas.pass_id == pid)
        rows = rows[np.argsort(meas.t_s[rows])]
        y[rows] += _ar1(meas.t_s[rows], rng)
    meas.observed = y
    start = truth.rv + rng.standard_normal(6) * np.array([100.0, 100.0, 100.0, 0.1, 0.1, 0.1])
    pb.priors[0].centre[:] = start
    pb.params.set_values(start)
    return pb


def test_filter_with_the_passes_ar1_noise_equals_estimates_gls(case):
    """Simulated range-rate with AR(1) noise of known phi and sigma on every pass: REML finds
    AR(1) on the passes; the iterated smoother with those models as Gauss–Markov states equals
    estimate's GLS (--noise auto, its own REML) at the epoch within 0.1 sigma, sigmas within 10 %;
    the noise models taken from the white iterated smoother's residuals, as filter_passes does."""
    pb = _problem(case, 1)
    fo = FilterOptions(problem=case[3], smooth=True, iterations=6, edit_sigma=None)
    white = FilterOptions(problem=case[3], smooth=True, iterations=6, edit_sigma=None)
    sw_w, hist_w = fr.run(pb, white)
    noise = pass_noise(pb, fo, sw_w.residuals("s"))      # as filter_passes: on the white smoother's residuals
    models = [v["model"] for v in noise.report.values()]
    print("models:", models)
    assert models.count("ar1") >= 7, noise.report
    taus = [v["ar1_tau_s"] for v in noise.report.values() if v["model"] == "ar1"]
    print("AR(1) tau (s):", np.round(taus, 1))
    assert 20.0 < np.median(taus) < 180.0, taus
    sw, hist = fr.run(pb, fo, None, noise)
    x, p = sw.absolute("s", sw.epoch_step)

    pe = _problem(case, 1)
    sol, _, report = estimate_solve(pe, case[3])
    assert [v["model"] for v in report.values()] == models
    sig = np.sqrt(np.diag(sol.covariance))
    z = (x - sol.values) / sig
    print("filter - estimate (sigma):", np.round(z, 4), "sigma ratio:", np.round(np.sqrt(np.diag(p)) / sig, 4))
    assert np.max(np.abs(z)) < 0.1, z
    assert np.max(np.abs(np.sqrt(np.diag(p)) / sig - 1.0)) < 0.1
    # REML keeps the shortest passes white (too few samples to pass its test), so the innovations
    # are not all white; with the models they are much nearer their variance than without
    nis = {r["code"]: r["value"] for r in filter_quality(pb, sw, hist, fo).reasons}["innovations"]
    q_w = filter_quality(pb, sw_w, hist_w, white)
    nis_w = {r["code"]: r["value"] for r in q_w.reasons}["innovations"]
    print(f"NIS per sample: {nis:.3f} with the passes' models, {nis_w:.3f} white ({q_w.verdict})")
    assert nis < 0.5 * nis_w and q_w.verdict != "ok"
