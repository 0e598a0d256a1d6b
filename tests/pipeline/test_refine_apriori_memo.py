"""The refinement's a-priori test (pipeline/refine/gates.refinement_apriori_test) given again for the
same refinement and solution (the gates' first solution, tested again by the quality report):
against the test made afresh, and made afresh for another solution."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from trackproc.io.statefile import State
from trackproc.pipeline.refine import RefineOptions, gates, prepare

from test_refine import EOP, EPOCH, STALE_RV, scenario, table


def test_the_same_solution_gets_the_same_test_and_another_its_own():
    _, _, sim = scenario(noise=False)
    stale = State.from_vectors(EPOCH, STALE_RV[:3], STALE_RV[3:])
    ref = prepare(table(sim), stale, None, RefineOptions(), EOP)
    sol, kkt, _ = gates.solve_weighted(ref)
    first = gates.refinement_apriori_test(ref, sol, kkt)
    again = gates.refinement_apriori_test(ref, sol, kkt)
    assert first == again == gates._apriori_test(ref, sol, kkt) and first is not again
    again["conflict"] = "changed by a caller"
    assert gates.refinement_apriori_test(ref, sol, kkt) == first          # a copy each time
    moved = replace(sol, values=np.asarray(sol.values, float) + np.r_[50.0, np.zeros(len(sol.values) - 1)])
    other = gates.refinement_apriori_test(ref, moved, kkt)
    assert other == gates._apriori_test(ref, moved, kkt) and other["chi2"] != first["chi2"]
