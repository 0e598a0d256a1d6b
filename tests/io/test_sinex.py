"""SINEX station coordinates: positions + velocities at the data epoch, solution spans, eccentricities.

References: closed forms (X0 + V (t - t0), the UNE vector in the local frame) on small SINEX
texts; the real SLRF2014 + ILRS eccentricity files for the LAGEOS-2 stations.
"""

import numpy as np
import pytest

from trackproc.dynamics.geodesy import enu_matrix, geodetic_to_itrf
from trackproc.errors import InputError
from trackproc.io.sinex import looks_like_sinex, parse_sinex_epoch, sinex_stations
from trackproc.io.stations import read_stations

from realdata import REALDATA

SNX = """%=SNX 2.01 JCT 20:119:43200 JCT 79:215:00000 20:119:43200 C 01338 2 X V
+SOLUTION/EPOCHS
*Code PT SOLN T Data_start__ Data_end____ Mean_epoch__
 7090  A    1 C 83:011:58876 12:001:00000 99:007:13417
 7090  A    2 C 12:001:00000 00:000:00000 15:001:00000
-SOLUTION/EPOCHS
+SOLUTION/ESTIMATE
*Index TYPE__ CODE PT SOLN _REF_EPOCH__ UNIT S __ESTIMATED VALUE____ _STD_DEV___
   205 STAX   7090  A    1 10:001:00000 m    2 -.238900753398029E+07 0.51901E-03
   206 STAY   7090  A    1 10:001:00000 m    2 0.504332944749889E+07 0.30033E-03
   207 STAZ   7090  A    1 10:001:00000 m    2 -.307852422322662E+07 0.22901E-03
   211 STAX   7090  A    2 10:001:00000 m    2 -.238900753398029E+07 0.51901E-03
   212 STAY   7090  A    2 10:001:00000 m    2 0.504332944749889E+07 0.30033E-03
   213 STAZ   7090  A    2 10:001:00000 m    2 -.307852422322662E+07 0.22901E-03
   214 VELX   7090  A    2 10:001:00000 m/y  2 -.468389138240797E-01 0.34434E-04
   215 VELY   7090  A    2 10:001:00000 m/y  2 0.839461295243685E-02 0.22507E-04
   216 VELZ   7090  A    2 10:001:00000 m/y  2 0.509471988578335E-01 0.25057E-04
-SOLUTION/ESTIMATE
+SITE/ECCENTRICITY
*Code PT SOLN T Data_start__ Data_end____ AXE Up______ North___ East____
 7090  A    1 L 79:182:00000 14:079:86399 UNE   9.0000   9.0000   9.0000        70900501
 7090  A    1 L 14:080:00000 00:000:00000 UNE   3.1827  -0.0064   0.0194        70900513
-SITE/ECCENTRICITY
"""
X0 = np.array([-2389007.53398029, 5043329.44749889, -3078524.22322662])
V = np.array([-0.0468389138240797, 0.00839461295243685, 0.0509471988578335])


def _itrf(st):
    return geodetic_to_itrf(np.radians(st.lat_deg), np.radians(st.lon_deg), st.height_m)


def test_epochs():
    assert parse_sinex_epoch("10:001:00000") == np.datetime64("2010-01-01T00:00:00", "ns")
    assert parse_sinex_epoch("99:365:43200") == np.datetime64("1999-12-31T12:00:00", "ns")
    assert parse_sinex_epoch("00:000:00000") is None
    assert looks_like_sinex(SNX.encode())


def test_position_propagated_with_velocity_and_eccentricity_applied():
    epoch = np.datetime64("2016-02-13T12:00:00", "ns")
    st = sinex_stations(SNX.encode(), "s.snx", epoch)["7090"]
    dt_y = (epoch - np.datetime64("2010-01-01", "ns")) / np.timedelta64(1, "s") / (365.25 * 86400)
    marker = X0 + V * dt_y                                      # solution 2 (solution 1 ended in 2012)
    from trackproc.dynamics.geodesy import itrf_to_geodetic

    lat, lon, _ = itrf_to_geodetic(marker)
    expected = marker + enu_matrix(lat, lon).T @ np.array([0.0194, -0.0064, 3.1827])
    assert np.linalg.norm(_itrf(st) - expected) < 1e-4
    # the velocity moved it by ~0.4 m since 2010: the epoch matters
    assert np.linalg.norm(V * dt_y) > 0.4


def test_old_solution_before_the_break_and_its_eccentricity():
    epoch = np.datetime64("2005-01-01T00:00:00", "ns")
    st = sinex_stations(SNX.encode(), "s.snx", epoch)["7090"]
    from trackproc.dynamics.geodesy import itrf_to_geodetic

    lat, lon, _ = itrf_to_geodetic(X0)                          # solution 1: no velocity given
    expected = X0 + enu_matrix(lat, lon).T @ np.array([9.0, 9.0, 9.0])
    assert np.linalg.norm(_itrf(st) - expected) < 1e-4


def test_errors_are_one_line():
    with pytest.raises(InputError, match="no SOLUTION/ESTIMATE"):
        sinex_stations(b"%=SNX 2.01\n+SITE/ID\n-SITE/ID\n", "e.snx", np.datetime64("2016-01-01", "ns"))
    bad = SNX.replace("0.504332944749889E+07 0.30033E-03\n   207", "0.50433x944749889E+07 0.30033E-03\n   207")
    with pytest.raises(InputError, match="invalid SINEX estimate") as err:
        sinex_stations(bad.encode(), "e.snx", np.datetime64("2016-01-01", "ns"))
    assert "row" in str(err.value) and "\n" not in str(err.value)


def test_read_stations_dispatches_and_needs_an_epoch(tmp_path):
    path = tmp_path / "s.snx"
    path.write_text(SNX)
    with pytest.raises(InputError, match="epoch of the data"):
        read_stations(str(path))
    assert set(read_stations(str(path), epoch=np.datetime64("2016-02-13", "ns"))) == {"7090"}


SLRF = REALDATA / "orekit-lageos2" / "SLRF2014_POS+VEL_2030.0_200428.snx"
ECC = REALDATA / "orekit-lageos2" / "ecc_une.snx"


@pytest.mark.realdata
@pytest.mark.skipif(not SLRF.exists(), reason="real data not available")
def test_real_slrf2014_with_ilrs_eccentricities():
    epoch = np.datetime64("2016-02-13T00:00:00", "ns")
    plain = read_stations(str(SLRF), epoch=epoch)
    with_ecc = read_stations(str(SLRF), epoch=epoch, eccentricities=str(ECC))
    # 7090 Yarragadee: the ILRS eccentricity (valid since 2014-03-21) is 3.1827 m up
    assert with_ecc["7090"].height_m - plain["7090"].height_m == pytest.approx(3.1827, abs=1e-3)
    # 7941 Matera: zero eccentricity; its geodetic position as Orekit's tutorial lists it
    assert with_ecc["7941"].lat_deg == pytest.approx(40.648672, abs=2e-6)
    assert with_ecc["7941"].lon_deg == pytest.approx(16.704613, abs=2e-6)
    assert with_ecc["7941"].height_m == pytest.approx(536.98049, abs=0.01)
