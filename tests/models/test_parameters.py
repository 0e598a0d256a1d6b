"""Estimated-parameter registry: names, units, scales, a-priori, selection, duplicates."""

import math

import numpy as np
import pytest

from trackproc.models import parameters as pm


def test_state_and_bias_drivers_in_order_with_units():
    ps = pm.ParameterSet(pm.state_drivers([7e6, 1.0, 2.0, 3.0, 7.5e3, 4.0]))
    ps.add(pm.range_bias("KIR", apriori_sigma=50.0))
    ps.add(pm.doppler_offset("KIR-001"))
    ps.add(pm.doppler_drift("KIR-001", epoch_s=12.5))
    ps.add(pm.az_bias("ZHY"))
    ps.add(pm.el_bias("ZHY"))
    assert ps.names == ["x", "y", "z", "vx", "vy", "vz", "range_bias:KIR", "doppler_offset:KIR-001",
                        "doppler_drift:KIR-001", "az_bias:ZHY", "el_bias:ZHY"]
    assert ps.units() == ["m", "m", "m", "m/s", "m/s", "m/s", "m", "Hz", "Hz/s", "rad", "rad"]
    assert ps["doppler_drift:KIR-001"].epoch_s == 12.5
    assert ps["range_bias:KIR"].family == "range_bias" and ps["range_bias:KIR"].key == "KIR"
    assert ps["vx"].family == "state" and ps["vx"].key is None
    np.testing.assert_array_equal(ps.values()[:6], [7e6, 1.0, 2.0, 3.0, 7.5e3, 4.0])
    mask, centre, sigma = ps.apriori()
    assert mask.tolist() == [False] * 6 + [True] + [False] * 4
    assert sigma[6] == 50.0 and centre[6] == 0.0 and math.isnan(sigma[0])


def test_duplicate_names_are_an_error():
    ps = pm.ParameterSet([pm.range_bias("KIR")])
    with pytest.raises(pm.DuplicateParameterError, match="range_bias:KIR"):
        ps.add(pm.range_bias("KIR"))
    with pytest.raises(pm.DuplicateParameterError):
        pm.ParameterSet(pm.state_drivers(np.zeros(6)) + pm.state_drivers(np.zeros(6)))


def test_selection_and_set_values():
    ps = pm.ParameterSet(pm.state_drivers(np.arange(6.0)) + [pm.range_bias("A"), pm.range_bias("B")])
    ps["range_bias:A"].selected = False
    assert ps.selected_names[-1] == "range_bias:B" and len(ps.selected) == 7
    assert ps.index("range_bias:B") == 6
    with pytest.raises(ValueError, match="not selected"):
        ps.index("range_bias:A")
    ps.set_values(np.arange(7.0) + 10)
    assert ps["range_bias:B"].value == 16.0 and ps["range_bias:A"].value == 0.0
    assert ps["x"].normalized() == pytest.approx(10.0 / ps["x"].scale)
    with pytest.raises(ValueError):
        ps.set_values(np.zeros(3))


@pytest.mark.parametrize("kwargs, match", [
    (dict(name="bad name", unit="m"), "without spaces"),
    (dict(name="", unit="m"), "non-empty"),
    (dict(name="p", unit="m", scale=0.0), "scale"),
    (dict(name="p", unit="m", scale=math.nan), "scale"),
    (dict(name="p", unit="m", apriori_sigma=-1.0), "a-priori"),
    (dict(name="p", unit="m", reference=math.inf), "finite"),
    (dict(name="p", unit="m", reference=5.0, bounds=(0.0, 1.0)), "outside bounds"),
])
def test_invalid_drivers(kwargs, match):
    with pytest.raises(ValueError, match=match):
        pm.ParameterDriver(**kwargs)


def test_split_name():
    assert pm.split_name("doppler_offset:DT-3") == ("doppler_offset", "DT-3")
    assert pm.split_name("vz") == ("state", None)
    for bad in ("range_bias", "range_bias:", "clock:KIR", "q"):
        with pytest.raises(ValueError, match="unknown parameter name"):
            pm.split_name(bad)
