"""``Problem.model`` keeps its last results (a refinement evaluates its solution again in the
noise model and the scans): what it hands out must be what a fresh problem computes, for the
same parameters and fixed drivers, and never an array a caller could change under it."""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import timescales as ts
from trackproc.io.passfile import PassTable
from trackproc.io.statefile import State
from trackproc.io.stations import Station
from trackproc.pipeline.estimate import EstimateOptions, build_problem
from trackproc.pipeline.od import problem as od_problem
from trackproc.pipeline.simulate import SimulateOptions, simulate

EPOCH = "2026-03-20T09:30:00.000Z"
TRUTH = State.from_vectors(EPOCH, np.array([3774841.0, -1538034.0, 5924146.0]), np.array([-4816.6, 3936.4, 4091.1]))
STATIONS = {"KIR": Station("KIR", 67.857, 20.964, 400.0), "MAD": Station("MAD", 40.43, -4.25, 830.0)}
EOP = ts.EarthOrientation.constant(0.1)


def _problem():
    sim = simulate(TRUTH, STATIONS, SimulateOptions(duration_s=4 * 3600, step_s=60.0, seed=3, kinds=("range",),
                                                    range_bias_m={"KIR": 50.0, "MAD": -30.0}), EOP)
    return build_problem([("sim.parquet", PassTable(sim.frame, sim.meta))], TRUTH, None,
                         EstimateOptions(range_bias=True), EOP)


def test_a_repeated_evaluation_is_a_fresh_one_and_not_shared():
    pb, fresh = _problem(), _problem()
    x = pb.x0 + np.r_[100.0, -50.0, 20.0, 0.1, 0.0, -0.1, np.zeros(pb.x0.size - 6)]
    h1, j1 = pb.model(x)
    count = pb.evaluations
    h1[:] = np.nan                                   # a caller's change must not reach the kept result
    j1[:] = np.nan
    h2, j2 = pb.model(x)
    assert pb.evaluations == count                   # kept, not evaluated again
    hf, jf = fresh.model(x)
    assert np.array_equal(h2, hf) and np.array_equal(j2, jf)
    assert np.isfinite(h2).all() and h2 is not pb.model(x)[0]


def test_a_fixed_drivers_new_value_or_other_parameters_evaluate_again():
    pb, fresh = _problem(), _problem()
    for problem in (pb, fresh):                      # the MAD bias held at 10 m, not estimated
        driver = next(d for d in problem.params if d.name == "range_bias:MAD")
        driver.selected, driver.value = False, 10.0
    x = pb.x0
    h_10 = pb.model(x)[0]
    next(d for d in pb.params if d.name == "range_bias:MAD").value = 25.0
    h_25 = pb.model(x)[0]
    mad = pb.meas.station == "MAD"
    assert mad.any() and np.allclose(h_25[mad] - h_10[mad], 15.0, atol=1e-6)   # the bias, not the kept result
    assert np.array_equal(h_25[~mad], h_10[~mad])
    next(d for d in fresh.params if d.name == "range_bias:MAD").value = 25.0
    assert np.array_equal(h_25, fresh.model(x)[0])
    # more distinct parameter vectors than it keeps: the oldest is evaluated again, the same numbers
    count = pb.evaluations
    for k in range(od_problem.MODEL_MEMO + 1):
        pb.model(x + np.r_[float(k + 1), np.zeros(x.size - 1)])
    assert pb.evaluations == count + od_problem.MODEL_MEMO + 1
    assert np.array_equal(pb.model(x)[0], h_25) and pb.evaluations == count + od_problem.MODEL_MEMO + 2


def test_values_without_the_jacobian_are_the_models_values():
    """``Problem.values`` (a step rule's trial point: no STM, no partials) gives the numbers
    ``Problem.model`` gives, bit for bit, on a fresh problem and from the kept results."""
    pb, fresh = _problem(), _problem()
    x = pb.x0 + np.r_[300.0, -80.0, 40.0, 0.2, -0.1, 0.05, 5.0 * np.ones(pb.x0.size - 6)]
    h, _ = pb.model(x)
    count = fresh.evaluations
    assert np.array_equal(fresh.values(x), h)
    assert fresh.evaluations == count + 1 and not fresh.__dict__.get("_memo")   # values alone are not kept
    assert np.array_equal(pb.values(x), h)                                      # from the kept result


def test_near_the_start_only_the_additive_drivers_moved_is_the_start_evaluation_shifted():
    """``Problem.model_near`` (a refinement's stale-state test: the stale state with the refined
    offsets) from the start point's result: the range biases add to the samples, so the values
    are the start's plus their partials times the change, the Jacobian the start's — what a fresh
    problem evaluates there, without an evaluation; any other parameter moved is evaluated."""
    pb, fresh = _problem(), _problem()
    x0 = pb.x0
    pb.model(x0)                                     # the solve's start
    count = pb.evaluations
    x = x0 + np.r_[np.zeros(6), 40.0 * np.arange(1, x0.size - 5)]
    h, j = pb.model_near(x)
    assert pb.evaluations == count
    hf, jf = fresh.model(x)
    assert np.allclose(h, hf, rtol=0.0, atol=1e-8) and np.array_equal(j, jf)
    moved = x.copy()
    moved[0] += 1.0                                  # the state: not additive, evaluated
    h2, j2 = pb.model_near(moved)
    assert pb.evaluations == count + 1
    assert np.array_equal(h2, fresh.model(moved)[0]) and np.array_equal(j2, fresh.model(moved)[1])


def test_epoch_frame_is_the_propagators_frame_kept_per_epoch_and_eop():
    """``epoch_frame`` (a batch's stale state is moved from one epoch for every pass) is the frame
    ``propagator.propagate`` makes by default, made again for another EOP object or epoch."""
    from trackproc.dynamics import propagator

    t = np.datetime64("2026-03-20T09:30:00.123456789", "ns")
    jd1, jd2 = ts.datetime64_to_jd_utc(t)
    want = propagator.reference_frame(float(jd1), float(jd2), EOP)
    got = od_problem.epoch_frame(t, EOP)
    for a in ("q", "w", "era0", "omega", "ref_jd_utc"):
        np.testing.assert_array_equal(np.asarray(getattr(got, a)), np.asarray(getattr(want, a)))
    assert od_problem.epoch_frame(t, EOP) is got
    assert od_problem.epoch_frame("2026-03-20T09:30:00.123456789Z", EOP) is got
    other = ts.EarthOrientation.constant(0.3)
    assert od_problem.epoch_frame(t, other) is not got
    assert od_problem.epoch_frame(t, other).era0 != got.era0
    assert od_problem.epoch_frame(t + np.timedelta64(60, "s"), EOP).era0 != got.era0
    traj = propagator.propagate(TRUTH.r_m, TRUTH.v_m_s, t, [600.0], force="j2", eop=EOP)
    with_frame = propagator.propagate(TRUTH.r_m, TRUTH.v_m_s, t, [600.0], force="j2", eop=EOP, frame=got)
    np.testing.assert_array_equal(traj.state(600.0), with_frame.state(600.0))
