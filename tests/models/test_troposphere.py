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


class _Geometry:
    """Straight up from each station (elevation 90 deg) or along the horizon tilted by ``el``."""

    def __init__(self, el):
        self.u = np.stack([np.zeros_like(el), np.cos(el), np.sin(el)], -1)


def _meas(t_s, station):
    from trackproc.models.observation import MeasurementSet

    n = len(t_s)
    return MeasurementSet(t_s=np.asarray(t_s, float), kind=["range"] * n, station=station, pass_id=["p"] * n,
                          observed=np.zeros(n), sigma=np.ones(n), r_st=np.zeros((n, 3)), v_st=np.zeros((n, 3)),
                          gcrf_to_enu=np.broadcast_to(np.eye(3), (n, 3, 3)).copy())


def test_modifiers_interpolate_meteo_and_subtract_the_centre_of_mass_offset():
    from trackproc.models.modifiers import bind_all

    meas = _meas([0.0, 50.0, 100.0, 10.0], ["A", "A", "A", "B"])
    tropo = tp.TroposphereDelay("A", LAT, 2010.344, 0.532, meteo_t_s=[0.0, 100.0], pressure_hpa=[798.4188, 798.4188],
                                temperature_k=[300.15, 300.15], humidity_percent=[40.0, 40.0], spans_s=[(0.0, 60.0)])
    com = tp.CentreOfMassOffset(0.251)
    value = np.zeros(4)
    for b in bind_all([tropo, com], meas):
        b.apply(value, np.zeros((4, 6)), {}, {}, _Geometry(np.full(4, np.pi / 2)))
    # station A inside its span: zenith delay of the IERS case (water vapour from 40 %) minus the offset
    assert value[0] == pytest.approx(1.935226 - 0.251, abs=2e-5) and value[1] == pytest.approx(value[0])
    assert value[2] == pytest.approx(-0.251) and value[3] == pytest.approx(-0.251)   # outside the span; station B
    # no meteo: the standard atmosphere at the height, so a delay of the right size
    std = tp.TroposphereDelay("B", LAT, 2010.344)
    v = std.correction(meas, np.array([3]), _Geometry(np.full(4, np.radians(20.0))))
    p_std = tp.standard_meteo(2010.344)[0]
    assert v[0] == pytest.approx(tp.fcula_mapping(np.radians(20.0), LAT, 2010.344, 291.15 - 6.5e-3 * 2010.344)
                                 * 1.93 * p_std / 798.4188, rel=0.02)


def test_meteo_interpolated_between_records_and_held_at_the_ends():
    d = tp.TroposphereDelay("A", LAT, 100.0, meteo_t_s=[100.0, 0.0], pressure_hpa=[990.0, 1000.0],
                            temperature_k=[290.0, 280.0], humidity_percent=[np.nan, 40.0])
    p, t, rh = d.meteo_at([50.0, -10.0, 500.0])
    assert np.allclose(p, [995.0, 1000.0, 990.0]) and np.allclose(t, [285.0, 280.0, 290.0])
    assert np.allclose(rh, 40.0)                          # a missing value: the valid records only
    p0, t0, rh0 = tp.TroposphereDelay("A", LAT, 100.0).meteo_at([0.0])
    assert np.allclose([p0[0], t0[0], rh0[0]], [t_[0] for t_ in tp.standard_meteo(np.array([100.0]))])
