"""Mendes–Pavlis zenith delay and FCULa mapping against the IERS Conventions (2010) test case.

Reference: IERS TN36 section 9.2 test case (McDonald Observatory, as in Orekit's
MendesPavlisModelTest): ZHD 1.932992 m, ZWD 0.223375e-2 m, total 1.935226 m; FCULa at 15°
elevation, 2075 m: 3.80024367. The water-vapour pressure of the case is 14.322 hPa.
"""

import numpy as np
import pytest

from trackproc.models import troposphere as tp

LAT = np.radians(30.67166667)


def test_water_vapour_pressure_of_the_iers_case():
    assert tp.water_vapour_pressure_hpa(798.4188, 300.15, 40.0) == pytest.approx(14.322, abs=5e-4)


def test_zenith_delays_match_iers_conventions():
    hydro, wet = tp.zenith_delay_m(LAT, 2010.344, 798.4188, 14.322, 0.532)
    assert hydro == pytest.approx(1.932992, abs=5e-6)
    assert wet == pytest.approx(0.223375e-2, abs=5e-8)
    assert hydro + wet == pytest.approx(1.935226, abs=5e-6)


def test_fcula_mapping_matches_iers_conventions():
    assert tp.fcula_mapping(np.radians(15.0), LAT, 2075.0, 300.15) == pytest.approx(3.80024367, abs=5e-8)


def test_mapping_is_one_at_zenith_and_delay_falls_with_elevation():
    assert tp.fcula_mapping(np.pi / 2, LAT, 0.0, 290.0) == pytest.approx(1.0, abs=1e-9)
    el = np.radians(np.arange(10.0, 90.0, 8.0))
    d = tp.slant_delay_m(el, np.radians(45.0), 350.0, *tp.standard_meteo(350.0))
    assert np.all(np.diff(d) < 0) and 2.0 < d[-1] < 2.5 and 10.0 < d[0] < 15.0


def test_range_corrections_subtract_the_centre_of_mass_offset_and_fill_missing_meteo():
    n = 3
    corr = tp.RangeCorrections(rows=np.arange(n), lat_rad=np.full(n, LAT), height_m=np.full(n, 2010.344),
                               pressure_hpa=np.array([798.4188, np.nan, 798.4188]),
                               temperature_k=np.full(n, 300.15), humidity_percent=np.full(n, 40.0),
                               wavelength_um=np.full(n, 0.532), troposphere=True, com_offset_m=0.251)
    v = corr.values(np.full(n, np.pi / 2))
    assert v[0] == pytest.approx(1.935226 - 0.251, abs=2e-5)
    p_std = tp.standard_meteo(2010.344)[0]
    assert v[1] == pytest.approx(v[0] * p_std / 798.4188, rel=0.01)   # standard atmosphere, mostly hydrostatic
    off = tp.RangeCorrections(**{**corr.__dict__, "troposphere": False})
    assert np.allclose(off.values(np.zeros(n)), -0.251)
