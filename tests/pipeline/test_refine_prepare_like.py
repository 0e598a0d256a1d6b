"""A refinement prepared again from the one before (pipeline/refine/assemble.prepare ``like``: the
traverse re-solves, the drift re-preparation) reuses the stations' GCRF geometry and the station
model. Independent reference: the same preparation from scratch (the IAU 2006/2000A transform of
every sample), to the bit."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from trackproc.io.statefile import State
from trackproc.pipeline.od import samples
from trackproc.pipeline.refine import RefineOptions, prepare

from test_refine import EOP, EPOCH, STALE_RV, scenario, table


def test_prepared_again_like_the_first_is_prepared_from_scratch(monkeypatch):
    _, _, sim = scenario(noise=False)
    tab = table(sim)
    stale = State.from_vectors(EPOCH, STALE_RV[:3], STALE_RV[3:])
    first = prepare(tab, stale, None, RefineOptions(), EOP)
    later = replace(first.options, traverse_epoch=first.problem.epoch + np.timedelta64(1_500_000_000, "ns"))
    for opt in (later, replace(first.options, doppler_bias="offset+drift")):
        again = prepare(tab, stale, None, opt, EOP, curve=first.curve, like=first)
        fresh = prepare(tab, stale, None, opt, EOP, curve=first.curve)
        for f in fields(fresh.problem.meas):
            a, b = getattr(again.problem.meas, f.name), getattr(fresh.problem.meas, f.name)
            assert np.array_equal(a, b), f.name
        assert np.array_equal(again.x0, fresh.x0) and again.names == fresh.names
        t = fresh.problem.meas.t_s
        assert np.array_equal(again.station_model.state(t)[0], fresh.station_model.state(t)[0])
    # the moved epoch counts the same samples from 1.5 s later
    def no_transform(*a, **k):
        raise AssertionError("the stations' geometry transformed again")

    monkeypatch.setattr(samples.geodesy, "station_gcrf", no_transform)
    moved = prepare(tab, stale, None, later, EOP, curve=first.curve, like=first)
    assert np.allclose(first.problem.meas.t_s - moved.problem.meas.t_s, 1.5, atol=1e-9)
    assert moved.problem.meas.r_st is not first.problem.meas.r_st          # a copy, not shared
