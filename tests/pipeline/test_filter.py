"""``trackproc filter`` against independent references: the batch least squares of ``estimate``
on the same data (zero process noise: the iterated smoother is the batch solution), a simulated
unmodelled 1 mm/s manoeuvre (without process noise the verdict says the filter diverges; with
the documented state noise compensation it is ok and its covariance covers the truth: NEES),
and the carried state (two nights in two runs = one run over both)."""

from pathlib import Path

import numpy as np
import pytest

from trackproc.io.eop import earth_orientation
from trackproc.io.passfile import PassTable, read_pass_table
from trackproc.io.statefile import parse_state, read_state, state_json
from trackproc.io.stations import read_stations
from trackproc.pipeline.estimate import EstimateOptions, build_problem, estimate
from trackproc.pipeline.od.problem import initial_at_epoch
from trackproc.pipeline.filter import FilterOptions, filter_passes
from trackproc.pipeline.filter import run as fr
from trackproc.pipeline.filter.result import filter_quality
from trackproc.types.state import State

DATA = Path(__file__).resolve().parents[2] / "sample_data"


@pytest.fixture(scope="module")
def case():
    eop, _ = earth_orientation(None, None)
    tables = [("multistation", read_pass_table(str(DATA / "multistation.parquet")))]
    return eop, tables, read_stations(str(DATA / "stations.csv"))


@pytest.mark.parametrize("noise", ["white", "auto"])
def test_zero_process_noise_iterated_smoother_equals_estimate(case, noise):
    """14 passes of range + range-rate from three stations with range biases, a first guess 10 km
    and 5 m/s off with that a-priori: the smoothed state at the epoch and its covariance against
    estimate's (the same a-priori on the state and the biases, no editing on either side). With
    ``--noise auto`` (the default) on these white samples REML keeps every pass white in both, so
    the answer is the white one."""
    eop, tables, stations = case
    initial = read_state(str(DATA / "stale.json"), eop)
    eo = EstimateOptions(range_bias=True, apriori_sigma={"range_bias": 1000.0}, apriori_initial=True, noise=noise,
                         clip=None, kinds=["range", "range_rate"])
    est = estimate(tables, initial, stations, eo, eop)
    sol = est.solution
    res = filter_passes(tables, initial, stations, FilterOptions(problem=eo, smooth=True, iterations=8,
                                                                 edit_sigma=None), eop)
    st = res.state
    if noise == "auto":
        models = {k: v["model"] for k, v in res.state.diagnostics["noise"].items()}
        assert len(models) >= 10 and set(models.values()) == {"white"}, models
        assert {k: v["model"] for k, v in est.state.diagnostics["noise"].items()} == models
    assert list(st.parameters) == list(sol.names)
    assert np.datetime64(st.epoch, "ns") == np.datetime64(initial.epoch, "ns")
    z = (np.asarray(st.values) - sol.values) / sol.sigma
    assert np.max(np.abs(z)) < 0.01, z
    rel = np.abs(np.asarray(st.covariance) - sol.covariance) / np.sqrt(np.outer(np.diag(sol.covariance),
                                                                                 np.diag(sol.covariance)))
    assert rel.max() < 0.01, rel.max()
    assert res.iterations[-1]["max_change_sigma"] < 1e-3
    assert res.quality.verdict == "ok", res.quality.text()
    # the stale state 10 km off is replaced, by estimate's decision (moved 7822 m against 0.257 m)
    _same_decision(st.diagnostics["decision"], est.state.diagnostics["decision"])
    assert st.diagnostics["decision"]["action"] == "replaced"


def _manoeuvre_truth(case, dv=1e-3, at_s=4 * 3600.0):
    """The noiseless part of :func:`_manoeuvre_case`, the same for every seed: the filter's
    problem (a draw sets every input it changes), the manoeuvred initial state, the model values
    before and after the impulse, the manoeuvred trajectory."""
    eop, tables, stations = case
    truth = read_state(str(DATA / "truth_at_start.json"), eop)
    eo = EstimateOptions(apriori_sigma={"position": 100.0, "velocity": 0.1}, noise="white",
                         kinds=["range", "range_rate"])
    pb = build_problem(tables, truth, stations, eo, eop)
    x0 = truth.rv
    traj = pb.trajectory(x0)
    s_m = traj.state(np.array([at_s]))[0]
    x1 = x0 + np.linalg.solve(traj.stm(np.array([at_s]))[0],
                              np.concatenate([np.zeros(3), dv * s_m[3:] / np.linalg.norm(s_m[3:])]))
    return pb, truth, eo, at_s, pb.model(x0)[0], pb.model(x1)[0], pb.trajectory(x1)


def _manoeuvre_case(case, seed, dv=1e-3, at_s=4 * 3600.0, noiseless=None):
    """Range + range-rate at the multistation samples' times and sigmas of an orbit given an
    along-track 1 mm/s impulse 4 h into the arc (after the truth's model: the problem's own, J2),
    the filter starting 100 m / 0.1 m/s off with that a-priori. ``noiseless``: the draw-independent
    part from :func:`_manoeuvre_truth` (a Monte Carlo computes it once, not once per draw)."""
    pb, truth, eo, at_s, h0, h1, truth1 = noiseless or _manoeuvre_truth(case, dv, at_s)
    x0 = truth.rv
    rng = np.random.default_rng(seed)
    t = pb.meas.t_s
    pb.meas.observed = np.where(t < at_s, h0, h1) + pb.meas.sigma * rng.standard_normal(t.size)
    start = x0 + rng.standard_normal(6) * np.array([100.0, 100.0, 100.0, 0.1, 0.1, 0.1])
    pb.priors[0].centre[:] = start
    pb.params.set_values(start)
    return pb, eo, truth1


def _nees(pb, eo, truth1, snc, smooth=True):
    fo = FilterOptions(problem=eo, smooth=smooth, snc_accel=(snc,) * 3)
    sw, hist = fr.run(pb, fo)
    x, p = sw.absolute("f", sw.t_s.size - 1)
    e = x[:6] - truth1.state(np.array([sw.t_s[-1]]))[0]
    return sw, filter_quality(pb, sw, hist, fo), float(e @ np.linalg.solve(p[:6, :6], e))


def test_unmodelled_manoeuvre_diverges_without_process_noise_and_not_with_snc(case):
    pb, eo, truth1 = _manoeuvre_case(case, seed=0)
    sw, q, nees = _nees(pb, eo, truth1, 0.0)
    codes = {r["code"] for r in q.reasons if r["severity"] != "ok"}
    assert q.verdict != "ok" and {"innovations", "filter_smoother"} <= codes, q.text()
    assert "diverges" in next(r["message"] for r in q.reasons if r["code"] == "innovations")
    assert nees > 1000
    sw, q, nees = _nees(pb, eo, truth1, 3e-6)
    assert q.verdict == "ok", q.text()
    assert nees < 22.5          # chi2(6) 99.9 % point


@pytest.mark.slow
@pytest.mark.statistical
def test_manoeuvre_nees_monte_carlo():
    """100 draws of noise and first guess with the 1 mm/s manoeuvre and SNC 3e-6 m/s^2/sqrt(Hz):
    the mean NEES (6 states) of the last filtered state inside the 99 % band of chi2(600)/100
    (measured 5.50 in [5.15, 6.93]), and the verdict ok in at least 95 draws (measured 100)."""
    from trackproc.dynamics import jit

    eop, _ = earth_orientation(None, None)
    tables = [("multistation", read_pass_table(str(DATA / "multistation.parquet")))]
    c = (eop, tables, read_stations(str(DATA / "stations.csv")))
    nees, ok = [], 0
    noiseless = _manoeuvre_truth(c)
    # the compiled Taylor engine for every reference arc: alone, the filter's short segments take
    # the numpy engine (dynamics/taylor.py COMPILED_MIN_STEPS), half of a draw's CPU; the engines
    # agree to rounding (~1e-13), the mean NEES moves by 3e-9 of itself
    with jit.default("1"):
        for seed in range(100):
            pb, eo, truth1 = _manoeuvre_case(c, seed=seed, noiseless=noiseless)
            _, q, v = _nees(pb, eo, truth1, 3e-6, smooth=False)
            nees.append(v)
            ok += q.verdict == "ok"
    from scipy.stats import chi2

    lo, hi = chi2.ppf(0.005, 600) / 100, chi2.ppf(0.995, 600) / 100
    assert lo < np.mean(nees) < hi, np.mean(nees)
    assert ok >= 95


def _guess(case, seed, offset=None, sigma=(100.0, 0.1)):
    """A state file's state with a diagonal covariance (a stated prior, sigmas ``sigma`` m, m/s):
    the truth drawn within it (``seed``), or moved by ``offset`` (6,)."""
    eop = case[0]
    truth = read_state(str(DATA / "truth_at_start.json"), eop)
    sig = np.array([sigma[0]] * 3 + [sigma[1]] * 3)
    rv = truth.rv + (np.random.default_rng(seed).standard_normal(6) * sig if offset is None else offset)
    return State.from_vectors(truth.epoch, rv[:3], rv[3:], values=rv, sigma=sig, covariance=np.diag(sig ** 2))


def test_carried_state_equals_one_run_and_skips_older_passes(case, caplog):
    """Night 1 (passes before 15:00) filtered, its output given as --initial to a run over every
    pass: the passes night 1 saw are skipped by name, and the result equals one run over all
    (zero process noise, no editing: the filter is linear in the updates between references).
    From a first guess drawn within its 100 m / 0.1 m/s a-priori, so that night 1's filtered state
    is consistent: every run replaces its prior (from the 10 km stale state one sweep leaves night
    1's filtered state at NEES 40 against the truth, which night 2 contradicts)."""
    eop, tables, stations = case
    initial = _guess(case, 1)
    frame = tables[0][1].frame
    cut = frame["time"] < frame["time"].min() + np.timedelta64(5, "h")
    night1 = [("night1", PassTable(frame[cut.to_numpy()].reset_index(drop=True), tables[0][1].meta))]
    eo = EstimateOptions(range_bias=True, apriori_sigma={"range_bias": 1000.0, "position": 100.0, "velocity": 0.1},
                         noise="white", kinds=["range", "range_rate"])
    fo = FilterOptions(problem=eo, edit_sigma=None)
    first = filter_passes(night1, initial, stations, fo, eop)
    carried = parse_state(state_json(first.state), "night1.json", eop)
    assert carried.extra["filter"]["last_measurement"] == first.state.extra["filter"]["last_measurement"]
    second = filter_passes(tables, carried, stations, fo, eop)
    assert second.skipped and all(p in second.warnings[0] for p in second.skipped)
    assert second.state.extra["filter"]["carried_state"] is True
    both = filter_passes(tables, initial, stations, fo, eop)
    sigma = np.asarray(both.state.sigma)
    z = (np.asarray(second.state.values) - np.asarray(both.state.values)) / sigma
    assert np.max(np.abs(z)) < 0.05, z
    np.testing.assert_allclose(second.state.sigma, sigma, rtol=0.02)
    for run in (first, second, both):
        assert run.state.diagnostics["decision"]["action"] == "replaced", run.state.diagnostics["decision"]


def _first_pass(case):
    """The set's first pass alone (ZHY, 100 range + range-rate samples): one station's pass."""
    frame = case[1][0][1].frame
    first = frame.groupby(["station", "pass_id"])["time"].min().sort_values().index[0]
    sel = ((frame["station"] == first[0]) & (frame["pass_id"] == first[1])).to_numpy()
    return [("one", PassTable(frame[sel].reset_index(drop=True), case[1][0][1].meta))]


def _along(case, metres):
    truth = read_state(str(DATA / "truth_at_start.json"), case[0])
    return np.concatenate([metres * truth.v_m_s / np.linalg.norm(truth.v_m_s), np.zeros(3)])


def _same_decision(filtered: dict, batch: dict):
    assert filtered["action"] == batch["action"], (filtered, batch)
    assert filtered["apriori_source"] == batch["apriori_source"] == "stated"
    for key in ("probability_better", "moved_m", "moved_sigma_m"):
        assert (key in filtered) == (key in batch), key
        if key in batch:
            np.testing.assert_allclose(filtered[key], batch[key], rtol=1e-4, err_msg=key)
    if "apriori_test" in batch:
        assert filtered["apriori_test"]["dof"] == batch["apriori_test"]["dof"]
        np.testing.assert_allclose(filtered["apriori_test"]["statistic"], batch["apriori_test"]["statistic"],
                                   rtol=1e-4)


@pytest.mark.parametrize("start, action", [
    ("truth, 100 m / 0.1 m/s", "kept"),                # the data cannot show a gain: the initial state is the answer
    ("500 m along-track, 10 m / 0.01 m/s", "replaced"),  # 50 sigma off: 14 passes carry a looser a-priori
])
def test_decision_equals_estimates_with_zero_process_noise(case, start, action):
    """The shared policy (methods/estimation) on the iterated smoother at the epoch and on
    estimate's batch solution, the same problem (all 14 passes, range biases, no editing, zero
    process noise): the same action and the same numbers. A stated prior 50 sigma off is
    contradicted (a-priori innovation chi2 ~2500 over 6), but the passes of three stations
    determine the state without it and pass their tests: its covariance is scaled (the filter
    run again from it) and the solution replaces it, as estimate's. From the truth the data move
    the state by less than its error (probability 0.68 < 0.9): kept, the written state the
    initial one."""
    eop, tables, stations = case
    initial = (_guess(case, 0, offset=np.zeros(6)) if action == "kept" else
               _guess(case, 0, offset=_along(case, 500.0), sigma=(10.0, 0.01)))
    eo = EstimateOptions(range_bias=True, apriori_sigma={"range_bias": 1000.0}, apriori_initial=True, noise="white",
                         clip=None, kinds=["range", "range_rate"])
    est = estimate(tables, initial, stations, eo, eop)
    res = filter_passes(tables, initial, stations, FilterOptions(problem=eo, smooth=True, iterations=8,
                                                                 edit_sigma=None), eop)
    _same_decision(res.state.diagnostics["decision"], est.state.diagnostics["decision"])
    codes = {r["code"]: r["severity"] for r in res.quality.reasons}
    assert codes[action] == "ok" and res.quality.verdict == "ok", res.quality.text()
    if action == "kept":
        np.testing.assert_allclose(res.state.values[:6], initial.rv, rtol=0, atol=1e-6)
        np.testing.assert_allclose(np.asarray(res.state.covariance)[:6, :6], initial.covariance, rtol=1e-9)
    else:
        assert codes["apriori_conflict"] == "ok" and "stated accuracy was wrong" in res.quality.text(
            ) + str([r["message"] for r in res.quality.reasons])
        x, _ = res.sweep.absolute("s", res.sweep.epoch_step)
        np.testing.assert_array_equal(res.state.values, x)      # the (adapted) run's own state


@pytest.mark.parametrize("smooth", [True, False])
def test_one_pass_contradicting_a_stated_prior_is_declined(case, smooth):
    """One pass (ZHY, 100 samples) against a state file 500 m along-track off with a 10 m /
    1 cm/s covariance (50 sigma): the a-priori test fires (chi2 2461 over 3, limit 16.3) and one
    pass cannot determine the state without it (posterior/a-priori variance 1.00 after scaling):
    declined, verdict suspect, the written state the prior's — at the epoch with the smoother (the
    prior itself), at the last measurement without (the prior propagated there by estimate's own
    mapping, ``initial_at_epoch``); the decision as estimate's."""
    eop, _, stations = case
    one = _first_pass(case)
    initial = _guess(case, 0, offset=_along(case, 500.0), sigma=(10.0, 0.01))
    eo = EstimateOptions(range_bias=True, apriori_sigma={"range_bias": 1000.0}, apriori_initial=True, noise="white",
                         clip=None, kinds=["range", "range_rate"])
    res = filter_passes(one, initial, stations, FilterOptions(problem=eo, smooth=smooth, iterations=3 if smooth else 1,
                                                              edit_sigma=None), eop)
    d = res.state.diagnostics["decision"]
    assert d["action"] == "declined" and d["reason"].startswith("declined: ")
    assert res.quality.verdict == "suspect"
    assert res.state.extra["filter"]["declined_in_a_row"] == 1
    assert {r["code"]: r["severity"] for r in res.quality.reasons}["declined"] == "suspect"
    rv, cov = initial_at_epoch(initial, np.datetime64(res.state.epoch, "ns"), "j2", eop)
    np.testing.assert_allclose(res.state.values[:6], rv, rtol=0, atol=1e-3)
    np.testing.assert_allclose(np.asarray(res.state.covariance)[:6, :6], cov, rtol=1e-6, atol=1e-12)
    if smooth:
        est = estimate(one, initial, stations, eo, eop)
        _same_decision(d, est.state.diagnostics["decision"])
    else:
        assert np.datetime64(res.state.epoch, "ns") > np.datetime64(initial.epoch, "ns")


@pytest.mark.parametrize("action", ["declined", "kept", "replaced"])
def test_a_run_that_failed_its_own_tests_does_not_reject_a_written_prior(action):
    """When the prior is written (declined, kept), the filter's failed run (a diverged filter,
    most samples edited) says why the data were not used: the verdict is suspect, not rejected
    (the policy's exit 0); when the run's state is written (replaced), rejected stays rejected."""
    from trackproc.methods import quality as qm
    from trackproc.pipeline.filter import policy as fp

    q = qm.Quality()
    q.add("edited", "rejected", "90 of 100 samples edited beyond 5 sigma: the filter has diverged", 0.9, 0.5)
    test = {"test": "a-priori", "statistic": 40.0, "dof": 6, "limit": 22.5, "conflict": action == "declined"}
    decision = {"action": action, "reason": f"{action}: ...", "probability_better": 0.95}
    fp.add_reasons(q, fp.Outcome(np.zeros(6), np.eye(6), None, decision, test, None), "stated")
    assert q.verdict == ("rejected" if action == "replaced" else "suspect"), q.text()


def test_runs_that_decline_their_carried_state_are_counted_in_a_row():
    """A chain of nights each declining the state it carries is counted (the carried state, not the
    data, is then the likely culprit and the reason says so); a run that replaces or keeps, or
    starts from an orbit that is not a filter's output, starts the count again."""
    from types import SimpleNamespace

    from trackproc.pipeline.filter.result import declined_in_a_row

    declined, kept = {"action": "declined"}, {"action": "kept"}
    night = SimpleNamespace(extra={"filter": {"declined_in_a_row": 2}})
    assert declined_in_a_row(night, declined) == 3
    assert declined_in_a_row(night, kept) == 0
    assert declined_in_a_row(SimpleNamespace(extra={}), declined) == 1        # a TLE or a plain state file
    assert declined_in_a_row(SimpleNamespace(extra={"filter": {}}), declined) == 1  # a filter output before the count
    assert declined_in_a_row(None, None) == 0
