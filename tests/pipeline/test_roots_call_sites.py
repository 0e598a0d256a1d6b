"""The root finder of methods/roots.py at its pipeline call site: the traverse station
of the seed 004 Table 1 scenario (pipeline/refine/traverse.py) is the same, to the bit, with
scipy.optimize.brentq; the algorithm itself is compared with scipy's in tests/methods/test_roots.py."""

from __future__ import annotations

import pytest
from scipy import optimize

from trackproc.dynamics import timescales as ts
from trackproc.io.statefile import State
from trackproc.pipeline.refine import traverse, traverse_station

TRUTH = State.from_vectors("2026-03-20T09:30:00.000Z", [3774841.0, -1538034.0, 5924146.0], [-4816.6, 3936.4, 4091.1])


@pytest.mark.parametrize("cross_track_m, side", [(500e3, "left"), (900e3, "right")])
def test_traverse_station_is_the_one_scipy_finds(monkeypatch, cross_track_m, side):
    eop = ts.EarthOrientation()
    mine = traverse_station(TRUTH, cross_track_m=cross_track_m, side=side, eop=eop)
    monkeypatch.setattr(traverse, "brentq", optimize.brentq)
    ref = traverse_station(TRUTH, cross_track_m=cross_track_m, side=side, eop=eop)
    assert mine == ref
