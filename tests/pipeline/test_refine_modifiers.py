"""One place to add a bias kind (issue 15 item 5): a measurement modifier that owns its driver
(:mod:`trackproc.models.modifiers`) is estimated by ``estimate`` and by ``refine`` (pointwise and
the integral cost of seed 004) without any other edit — refine collects its drivers from the
modifiers exactly as estimate does, and parses no parameter name.

The toy kind, declared here only: a constant range-rate bias of a station (``rr_bias:STATION``,
m/s), its family unit registered in the vocabulary for the test. The reference: the bias added
to the simulated samples (0.02 m/s on 1 mm/s two-way range-rate of the seed 004 Table 1 pass),
recovered within 3 sigma, and the estimates without it unchanged in form."""

from __future__ import annotations

import numpy as np
import pytest

from trackproc import vocabulary
from trackproc.models import modifiers as md

BIAS = 0.02     # m/s, added to every simulated range-rate


class RangeRateBias(md.Modifier):
    """``rr_bias:STATION`` (m/s), added to the station's range-rates (coefficient 1)."""

    family, scale, description = "rr_bias", 1e-2, "constant range-rate bias (a toy kind)"

    def rows(self, meas) -> np.ndarray:
        return np.flatnonzero((meas.kind == "range_rate") & (meas.station == self.key))


@pytest.fixture(scope="module")
def biased():
    from test_refine import scenario, table

    _, _, sim = scenario(two_way_sigma_m_s=1e-3)
    t = table(sim)
    frame = t.frame.copy()
    frame["value"] = frame["value"] + BIAS
    return type(t)(frame, t.meta)


@pytest.fixture
def toy_kind(monkeypatch):
    monkeypatch.setitem(vocabulary.BIAS_UNITS, "rr_bias", "m/s")
    return RangeRateBias("TRV", apriori_sigma=0.1)


def _check(names, values, sigma):
    i = list(names).index("rr_bias:TRV")
    assert abs(values[i] - BIAS) < 3 * sigma[i] and sigma[i] < BIAS / 2, (values[i], sigma[i])


def test_a_toy_bias_kind_is_estimated_by_estimate(biased, toy_kind):
    from test_refine import EOP, STALE
    from trackproc.pipeline.estimate import EstimateOptions, estimate

    res = estimate([("pass", biased)], STALE, None, EstimateOptions(modifiers=(toy_kind,), apriori_initial=True), EOP)
    _check(res.solution.names, res.solution.values, res.solution.sigma)
    assert toy_kind.driver.value == 0.0                  # the caller's modifier is copied, not changed


@pytest.mark.parametrize("cost", ["pointwise", "integral"])
def test_a_toy_bias_kind_is_estimated_by_refine(biased, toy_kind, cost):
    from test_refine import EOP, STALE
    from trackproc.pipeline.refine import RefineOptions, refine

    res = refine(biased, STALE, None, RefineOptions(cost=cost, apriori=True, modifiers=(toy_kind,)), EOP)
    _check(res.names, res.state.values, res.state.sigma)
    assert res.state.extra["refinement"]["doppler_bias"] == []
