"""Measurement modifiers own their parameter drivers (issue 15 item 5, Orekit's
``getParametersDrivers()``/``modify()``): the registry covers the vocabulary, the estimator's
extended state is the modifiers' drivers (the same objects), a driver-free range correction
(troposphere-like) is applied on each evaluation's geometry, the oscillator wander concerns
one-way samples only, and ``r_ka`` is a registered parameter."""

from __future__ import annotations

import numpy as np
import pytest

from trackproc import vocabulary
from trackproc.constants import C_LIGHT, OMEGA_EARTH
from trackproc.dynamics import propagator
from trackproc.io.passfile import PassTable
from trackproc.io.statefile import State
from trackproc.io.stations import Station
from trackproc.dynamics import timescales as ts
from trackproc.models import modifiers as md
from trackproc.models import observation as ob
from trackproc.models import parameters as pm
from trackproc.pipeline.estimate import EstimateOptions, build_problem
from trackproc.pipeline.simulate import SimulateOptions, simulate

EPOCH = "2026-03-20T09:30:00.000Z"
STATE0 = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1])
CARRIER = 2.2e9
LAT_DEG, LON_DEG = 60.0, -10.0     # the satellite passes overhead in the first minutes


def _trajectory():
    return propagator.propagate(STATE0[:3], STATE0[3:], EPOCH, [-1.0, 3000.0], force="j2",
                                stm=True).raise_for_outcome()


def _meas(kinds, t, mode="one-way"):
    """One station on a rotating sphere, with a proper GCRF -> ENU rotation (an elevation that means something)."""
    ang = OMEGA_EARTH * t
    lat, lon0 = np.radians(LAT_DEG), np.radians(LON_DEG)
    lon = lon0 + ang
    r0 = 6.371e6
    r = r0 * np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.full_like(t, np.sin(lat))], -1)
    v = OMEGA_EARTH * np.stack([-r[:, 1], r[:, 0], np.zeros_like(t)], -1)
    east = np.stack([-np.sin(lon), np.cos(lon), np.zeros_like(t)], -1)
    north = np.stack([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.full_like(t, np.cos(lat))], -1)
    up = r / r0
    n = t.size
    return ob.MeasurementSet(t_s=t, kind=np.array(kinds, dtype=object), station=np.full(n, "S", dtype=object),
                             pass_id=np.full(n, "S-001", dtype=object), observed=np.zeros(n), sigma=np.ones(n),
                             r_st=r, v_st=v, gcrf_to_enu=np.stack([east, north, up], 1), carrier_hz=CARRIER,
                             mode=mode)


def test_every_bias_family_of_the_vocabulary_has_its_modifier_with_the_vocabulary_unit():
    assert set(md.FAMILIES) == set(vocabulary.BIAS_UNITS)
    for family, cls in md.FAMILIES.items():
        mod = cls("K", 1.0) if cls in (md.DopplerDrift, md.DopplerStep) else cls("K")
        (driver,) = mod.parameter_drivers()
        assert driver.name == f"{family}:K" and driver.unit == vocabulary.BIAS_UNITS[family]
        assert pm.split_name(driver.name) == (family, "K")
        assert type(md.from_name(driver.name, epoch_s=1.0)) is cls


def test_the_estimators_extended_state_is_the_modifiers_drivers():
    """Orekit's design: the estimator collects the drivers from the measurements' modifiers —
    the very objects, in order — and no driver is recovered by parsing its name."""
    stations = {"ZHY": Station("ZHY", 48.0, 35.0, 150.0), "KIR": Station("KIR", 67.857, 20.964, 400.0)}
    eop = ts.EarthOrientation.constant(0.1)
    sim = simulate(State.from_vectors(EPOCH, STATE0[:3], STATE0[3:]), stations,
                   SimulateOptions(duration_s=4 * 3600, step_s=60, seed=3, kinds=("range", "doppler")), eop)
    problem = build_problem([("sim", PassTable(sim.frame, sim.meta))], State.from_vectors(EPOCH, STATE0[:3],
                                                                                          STATE0[3:]),
                            stations, EstimateOptions(range_bias=["KIR"], doppler_bias="offset+drift"), eop)
    owned = md.collect_drivers(b.modifier for b in problem.modifiers)
    assert [d.name for d in owned] == problem.params.names[6:]
    assert all(problem.params[d.name] is d for d in owned)
    kinds = {type(b.modifier) for b in problem.modifiers}
    assert kinds == {md.RangeBias, md.DopplerOffset, md.DopplerDrift, md.OscillatorWander}
    # each bound modifier acts exactly on its own samples
    for b in problem.modifiers:
        if isinstance(b.modifier, md.RangeBias):
            assert set(problem.meas.kind[b.rows]) == {"range"} and set(problem.meas.station[b.rows]) == {"KIR"}
        elif isinstance(b.modifier, (md.DopplerOffset, md.DopplerDrift, md.OscillatorWander)):
            assert set(problem.meas.kind[b.rows]) == {"doppler"}
            assert set(problem.meas.pass_id[b.rows]) == {b.modifier.key}


class _Troposphere(md.RangeCorrection):
    """A mapping-function-like delay: zenith 2.3 m over sin(elevation)."""

    def delay(self, meas, rows, geometry):
        return 2.3 / np.sin(md.elevation(meas, rows, geometry))


def test_a_driver_free_range_correction_follows_the_geometry_and_adds_no_column():
    t = np.linspace(20.0, 300.0, 7)
    kinds = ["range", "elevation"] * 7
    tt = np.repeat(t, 2)
    meas = _meas(kinds, tt)
    traj = _trajectory()
    base, jac0, _ = ob.evaluate(meas, traj)
    tropo = _Troposphere("S").bind(meas)
    assert tropo.names == () and md.collect_drivers([tropo.modifier]) == []
    value, jac, _ = ob.evaluate(meas, traj, modifiers=[tropo])
    rng = meas.kind == "range"
    # the independent elevation: the estimator's own elevation observable at the same reception times
    el = base[~rng]
    assert np.all(el > 0.3)
    np.testing.assert_allclose(value[rng] - base[rng], 2.3 / np.sin(el), rtol=1e-9)
    np.testing.assert_array_equal(value[~rng], base[~rng])
    np.testing.assert_array_equal(jac, jac0)


def test_oscillator_wander_concerns_one_way_samples_only_and_changes_no_value():
    kinds = ["doppler", "range_rate", "range"] * 4
    t = np.linspace(300.0, 1500.0, len(kinds))
    mode = np.array(["one-way"] * 6 + ["two-way"] * 6, dtype=object)
    meas = _meas(kinds, t, mode)
    meas.a_st = np.zeros((len(t), 3))
    wander = md.OscillatorWander("S-001", walk=0.01)
    b = wander.bind(meas)
    assert b.rows.tolist() == [0, 1, 3, 4] and wander.parameter_drivers() == []
    value = np.zeros(len(t))
    b.apply(value, np.zeros((len(t), 6)), {}, {})
    assert not value.any()
    # a two-way pass alone: nothing to wander, and binding is no error (a bias with a driver would be)
    two = _meas(["doppler"] * 3, t[:3], "two-way")
    assert md.OscillatorWander("S-001").bind(two).rows.size == 0
    with pytest.raises(ValueError, match="acts on no measurement"):
        md.RangeBias("S").bind(two)


def test_drift_coefficients_are_the_offsets_times_the_elapsed_time():
    kinds = ["doppler", "range_rate"] * 3
    t = np.linspace(100.0, 600.0, 6)
    meas = _meas(kinds, t)
    off = md.DopplerOffset("S").bind(meas)
    drift = md.DopplerDrift("S", 150.0).bind(meas)
    np.testing.assert_allclose(off.coefficients()[::2], 1.0)
    np.testing.assert_allclose(off.coefficients()[1::2], -C_LIGHT / CARRIER)
    np.testing.assert_allclose(drift.coefficients(), off.coefficients() * (t - 150.0), rtol=1e-15)


def test_r_ka_is_a_registered_parameter():
    d = pm.orbit_radius(7.0e6)
    assert d.name == "r_ka" and d.unit == "m" and d.family == "r_ka" and d.key is None
    assert pm.split_name("r_ka") == ("r_ka", None)
    with pytest.raises(ValueError):
        pm.orbit_radius(-1.0)
