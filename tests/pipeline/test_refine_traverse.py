"""The refined orbit's own traverse point (pipeline/refine/traverse.model_traverse): its secant reads
the range-rate series of one prediction on the search grid instead of a new prediction per iterate.
Independent reference: scipy's brentq on range-rates each predicted on a segment centred at the
trial time itself (the series there at its expansion point), for both range-rate models."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import optimize

from trackproc.dynamics import measurement_spectra as ms
from trackproc.dynamics import propagator
from trackproc.io.statefile import State
from trackproc.pipeline.refine import RefineOptions, prepare
from trackproc.pipeline.refine import traverse as tv

from test_refine import EOP, EPOCH, STALE_RV, scenario, table


@pytest.fixture(scope="module")
def base():
    _, _, sim = scenario(noise=False)
    stale = State.from_vectors(EPOCH, STALE_RV[:3], STALE_RV[3:])
    return table(sim), stale


def _centred_rr(ref, traj, m):
    return float(ms.predict(traj, ref.station_model, np.array([m]), range_rate_model=ref.problem.range_rate_model,
                            partials=False).range_rate_m_s[0])


@pytest.mark.parametrize("model", ["doppler", "instantaneous"])
def test_traverse_is_the_root_of_centred_predictions(base, model):
    tab, stale = base
    ref = prepare(tab, stale, None, RefineOptions(range_rate_model=model), EOP)
    # the stale state is off the pass's own traverse point: a root away from the epoch
    x = np.asarray(ref.x0, float).copy()
    x[3:6] *= 1.0 + 2e-4
    got = tv.model_traverse(ref, x)
    traj = propagator.propagate(x[:3], x[3:6], ref.problem.epoch, [-62.0, 62.0], force=ref.options.force,
                                frame=ref.problem.frame, eop=ref.problem.eop).raise_for_outcome()
    want = optimize.brentq(lambda m: _centred_rr(ref, traj, m), got - 0.5, got + 0.5, xtol=1e-13, rtol=1e-15)
    assert got is not None and abs(got) > 1e-3
    assert abs(got - want) < 1e-9
    # the series' range-rate across the grid agrees with centred predictions (m/s)
    t = np.linspace(-60.0, 60.0, 241)
    pred = ms.predict(traj, ref.station_model, t, range_rate_model=model, partials=False)
    for m in (-47.3, -0.21, got, 13.37, 59.9):
        assert abs(tv._series_range_rate(pred, t, m) - _centred_rr(ref, traj, m)) < 1e-7


def test_highest_elevation_from_the_traverse_series_is_the_predicted_one(base):
    tab, stale = base
    ref = prepare(tab, stale, None, RefineOptions(), EOP)
    x = np.asarray(ref.x0, float)
    t = ref.problem.meas.t_s
    traj = propagator.propagate(x[:3], x[3:6], ref.problem.epoch, [float(t.min()) - 1.0, float(t.max())],
                                force=ref.options.force, frame=ref.problem.frame,
                                eop=ref.problem.eop).raise_for_outcome()
    want = np.degrees(ms.predict(traj, ref.station_model, t, partials=False).elevation_rad)
    assert tv._top_from_grid(ref, x, t) is None          # no traverse search of x yet
    tv.model_traverse(ref, x)
    top = tv._top_from_grid(ref, x, t)
    assert top is not None and abs(top - want.max()) < 1e-9
    assert tv.max_elevation_deg(ref, x) == top
    # samples on one side of the top only: their highest is an end of the covered ones, not a top
    rising = t[(t > -50.0) & (t < -20.0)]
    assert tv._top_from_grid(ref, x, rising) is None
