"""``estimate --estimate-force``: the radiation-pressure and drag coefficients and a constant
empirical R/T/N acceleration as drivers of the extended state (issue 17 item 3).

Their Jacobian columns come from the propagator's parameter sensitivities (variational
equations) chained through the measurement partials; checked here against central differences
of the whole measurement model, and by recovering known values from simulated data (the truth
simulated with other Cr, Cd and accelerations than the estimator starts from).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest

from trackproc.dynamics import timescales as ts
from trackproc.dynamics.forces import ForceModel, Spacecraft
from trackproc.errors import InputError
from trackproc.io.icgem import load_field
from trackproc.io.passfile import PassTable
from trackproc.io.statefile import State
from trackproc.io.stations import Station
from trackproc.models import parameters as pm
from trackproc.pipeline.estimate import EstimateOptions, build_problem, estimate
from trackproc.pipeline.od.options import force_parameter_names
from trackproc.pipeline.simulate import SimulateOptions, simulate

EPOCH = "2026-03-20T09:30:00.000Z"
R0 = np.array([3774841.0, -1538034.0, 5924146.0])          # 810 km LEO
V0 = np.array([-4816.6, 3936.4, 4091.1])
STATIONS = {"ZHY": Station("ZHY", 48.0, 35.0, 150.0), "KIR": Station("KIR", 67.857, 20.964, 400.0),
            "MAD": Station("MAD", 40.43, -4.25, 830.0)}
BIASES = {"ZHY": 100.0, "KIR": -80.0, "MAD": 120.0}
TRUTH = State.from_vectors(EPOCH, R0, V0)
GUESS = State.from_vectors(EPOCH, R0 + [600.0, -500.0, 560.0], V0 + [0.6, -0.5, 0.6])
EOP = ts.EarthOrientation.constant(0.1)
#: 10 kg, 1 m² (area/mass 0.1 m²/kg): radiation pressure 7e-7 m/s², drag ~1e-7 m/s² at 810 km.
SPACECRAFT = Spacecraft(mass_kg=10.0, srp_area_m2=1.0, cr=1.3, drag_area_m2=1.0, cd=2.2)
#: What the simulated truth flies with (the estimator starts from SPACECRAFT and no acceleration).
TRUE_FORCES = {"cr": 1.8, "cd": 2.8, "empirical_r": 2e-8, "empirical_t": 5e-8, "empirical_n": -3e-8}
ALL = ("cr", "cd", "empirical_r", "empirical_t", "empirical_n")


def model(**values) -> ForceModel:
    # Sun and Moon left out: the truth and the estimate share the model, and the parameters' partials
    # do not depend on them (a third of the test's time)
    fm = ForceModel(field=load_field(degree=8, date=np.datetime64("2026-03-20")), srp=True, drag=True,
                    spacecraft=SPACECRAFT, eop=EOP, third_bodies=(), relativity=False)
    return fm.with_parameters(**values) if values else fm


@lru_cache(maxsize=None)
def simulated(hours: float, step: float):
    sim = simulate(TRUTH, STATIONS, SimulateOptions(duration_s=hours * 3600, step_s=step, seed=3,
                                                    kinds=("range", "range_rate"), range_bias_m=BIASES, force="full",
                                                    force_model=model(**TRUE_FORCES)), EOP)
    return [("sim.parquet", PassTable(sim.frame, sim.meta))]


def options(**kw) -> EstimateOptions:
    base = dict(range_bias=True, force="full", force_model=model(), estimate_force=["cr,cd,empirical-rtn"],
                noise="white")
    base.update(kw)
    return EstimateOptions(**base)


# ----------------------------------------------------------------------------- names and options

def test_force_parameter_names_and_drivers():
    assert force_parameter_names(["empirical-rtn", "cr"]) == ("cr", "empirical_r", "empirical_t", "empirical_n")
    assert force_parameter_names(["cd,empirical_t"]) == ("cd", "empirical_t")
    for bad in (["cr,cr"], ["leak"]):
        with pytest.raises(InputError) as err:
            force_parameter_names(bad)
        assert err.value.column == "--estimate-force"
    assert pm.split_name("cr") == ("cr", None)
    d = pm.force_parameter("cd", 2.2)
    assert d.unit == "1" and d.bounds == (0.0, math.inf) and d.family == "cd"
    assert pm.force_parameter("empirical_t", 0.0).unit == "m/s^2"


def test_force_parameters_become_drivers_after_the_state():
    tables = simulated(2.0, 120.0)
    problem = build_problem(tables, GUESS, STATIONS, options(apriori_sigma={"empirical": 1e-7, "cr": 0.5}), EOP)
    assert problem.names[:11] == ["x", "y", "z", "vx", "vy", "vz", *ALL]
    assert problem.params["cr"].reference == 1.3 and problem.params["empirical_t"].reference == 0.0
    assert problem.params["cr"].apriori_sigma == 0.5 and problem.params["empirical_n"].apriori_sigma == 1e-7
    assert problem.force_model.estimated == ALL


@pytest.mark.parametrize("change, match", [
    (dict(force="j2", force_model=None), "full force model"),
    (dict(force_model=ForceModel(field=load_field(degree=4)), estimate_force=["cr"]), "radiation pressure"),
    (dict(force_model=ForceModel(field=load_field(degree=4)), estimate_force=["cd"]), "drag"),
])
def test_force_parameters_the_model_cannot_carry_are_input_errors(change, match):
    with pytest.raises(InputError, match=match) as err:
        build_problem(simulated(2.0, 120.0), GUESS, STATIONS, options(**change), EOP)
    assert err.value.column == "--estimate-force"


def test_cli_estimate_force_needs_force_full(run_cli, tmp_path):
    result = run_cli(["estimate", "sample_data/multistation.parquet", "--initial", "sample_data/truth.json",
                      "--range-bias", "--estimate-force", "cr", "-o", tmp_path / "out.json"])
    assert result.exit_code == 2 and "--estimate-force" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "out.json").exists()


# ----------------------------------------------------------------------------- partials and recovery

@pytest.mark.slow
def test_force_parameter_columns_match_central_differences_of_the_measurement_model():
    from trackproc.dynamics import jit

    problem = build_problem(simulated(3.0, 60.0), GUESS, STATIONS,
                            options(estimate_force=["cr,cd,empirical-rtn,empirical-xyz,empirical-xyz-rate"]), EOP)
    x = problem.x0.copy()
    # 23 propagations of 3 h with 17 sensitivities, on the compiled integrator: alone, a 3 h run takes
    # the numpy path (integrator.use_compiled), ten times the CPU here; the compiled partials equal
    # the numpy path's for every parameter kind (tests/io/test_forces_jit.py)
    with jit.default("1"):
        _, jac = problem.model(x)
    # steps large against DOP853's step-selection noise (decimetres after eclipse crossings)
    for name, h in (("cr", 0.5), ("cd", 0.5), *((f"empirical_{c}", 5e-6) for c in "rtnxyz"),
                    *((f"empirical_{c}_rate", 5e-10) for c in "xyz")):
        k = problem.names.index(name)
        plus, minus = x.copy(), x.copy()
        plus[k] += h
        minus[k] -= h
        with jit.default("1"):
            ref = (problem.model(plus)[0] - problem.model(minus)[0]) / (2 * h)
        scale = np.abs(ref).max()
        assert scale > 0 and np.abs(jac[:, k] - ref).max() < 2e-2 * scale, name
        # the column is not the state's or another parameter's
        others = [j for j in range(6, 17) if j != k]
        assert all(np.abs(jac[:, j] - ref).max() > 0.1 * scale for j in others), name


@pytest.mark.slow
def test_simulated_cr_cd_and_empirical_acceleration_recovered_within_their_sigma():
    """12 h of ranges and range-rates from 3 stations; the truth flies with Cr 1.8, Cd 2.8 and an
    R/T/N acceleration of (2, 5, -3) x 1e-8 m/s², the estimate starts from Cr 1.3, Cd 2.2 and none."""
    res = estimate(simulated(12.0, 20.0), GUESS, STATIONS, options(), EOP)
    sol = res.solution
    truth = dict(zip(pm.STATE_NAMES, TRUTH.rv), **TRUE_FORCES, **{f"range_bias:{k}": v for k, v in BIASES.items()})
    z = {n: (v - truth[n]) / s for n, v, s in zip(sol.names, sol.values, sol.sigma)}
    assert sol.converged and all(abs(v) < 3.5 for v in z.values()), z
    # the data moved Cr from its start by many sigmas: the driver is estimated, not held
    cr = sol.names.index("cr")
    assert abs(1.3 - truth["cr"]) > 3 * sol.sigma[cr]
    assert 0.5 < res.state.diagnostics["variance_factor"] < 1.5
    doc = res.state.extra["estimation"]
    assert "propagator" in doc
    described = res.state.constants
    assert described["spacecraft"]["cr"] == pytest.approx(sol.values[cr])     # the metadata carry the estimate


def test_empirical_gcrf_acceleration_displaces_the_orbit_by_half_a_t_squared():
    """Closed form: a constant acceleration a along GCRF X moves the orbit by a t²/2 along X over a
    short time (the gravity gradient changes it by ~GM t²/r³, 1e-3 at t = 30 s)."""
    from trackproc.dynamics.propagator import propagate

    base = ForceModel(field=load_field(degree=4), third_bodies=(), relativity=False, eop=EOP)
    t, a = 30.0, np.array([2e-5, -1e-5, 3e-5])
    ref = propagate(R0, V0, EPOCH, [t], force=base).state(t)
    pushed = propagate(R0, V0, EPOCH, [t], force=base.with_parameters(
        empirical_x=a[0], empirical_y=a[1], empirical_z=a[2])).state(t)
    np.testing.assert_allclose(pushed[:3] - ref[:3], 0.5 * a * t * t, rtol=3e-3)
    np.testing.assert_allclose(pushed[3:] - ref[3:], a * t, rtol=3e-3)
    # a rate b (m/s³): the acceleration b t moves it by b t³/6
    b = a / 10.0
    grown = propagate(R0, V0, EPOCH, [t], force=base.with_parameters(
        empirical_x_rate=b[0], empirical_y_rate=b[1], empirical_z_rate=b[2])).state(t)
    np.testing.assert_allclose(grown[:3] - ref[:3], b * t ** 3 / 6, rtol=3e-3)
