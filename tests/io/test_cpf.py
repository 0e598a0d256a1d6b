"""ILRS CPF reader (positions ITRF -> GCRF) on a small text and the JAXA LAGEOS-2 prediction."""

import numpy as np
import pytest

from trackproc.errors import InputError
from trackproc.io.cpf import cpf_gcrf, parse_cpf

from realdata import REALDATA

CPF = """H1 CPF  1  SGF 2016  2 13  2  5441 lageos2
H2  9207002 5986    22195 2016  2 13  0  0  0 2016  2 13 23 54  0   300 1 1  0 0 0
H9
10 0 57431      0.00000  0   7049498.186   5346456.274   8307028.039
10 0 57431    300.00000  0   5742134.431   5922879.510   8932852.042
99
"""


def test_records_and_times():
    eph = parse_cpf(CPF.encode(), "x.sgf")
    assert eph.times[1] == np.datetime64("2016-02-13T00:05:00", "ns")
    assert eph.r_itrf[0, 2] == 8307028.039 and eph.target == "lageos2" and not eph.com_corrected


def test_gcrf_keeps_the_norm_and_rotates_about_z():
    eph = parse_cpf(CPF.encode(), "x.sgf")
    r = cpf_gcrf(eph)
    assert np.allclose(np.linalg.norm(r, axis=1), np.linalg.norm(eph.r_itrf, axis=1), atol=1e-6)
    assert abs(r[0, 2] - eph.r_itrf[0, 2]) < 3e4          # precession-nutation + polar motion only tilt z a little
    assert np.linalg.norm(r[0, :2] - eph.r_itrf[0, :2]) > 1e6   # Earth rotation angle moves x, y


def test_bad_files():
    with pytest.raises(InputError, match="reference frame"):
        parse_cpf(CPF.replace("300 1 1  0 0 0", "300 1 1  1 0 0").encode(), "x.sgf")
    with pytest.raises(InputError, match="invalid CPF position record"):
        parse_cpf(CPF.replace("5922879.510", "59x").encode(), "x.sgf")
    with pytest.raises(InputError, match="before the H1 header"):
        parse_cpf(b"10 0 57431 0.0 0 1 2 3\n", "x.sgf")
    with pytest.raises(InputError, match="not a CPF"):
        parse_cpf(b"99\n", "x.sgf")


SGF = REALDATA / "orekit-lageos2" / "lageos2_cpf_160213_5441.sgf"


@pytest.mark.realdata
@pytest.mark.skipif(not SGF.exists(), reason="real data not available")
def test_jaxa_lageos2_prediction():
    eph = parse_cpf(SGF.read_bytes(), str(SGF))
    assert len(eph.times) == 288 and np.all(np.diff(eph.times) == np.timedelta64(300, "s"))
    radius = np.linalg.norm(eph.r_itrf, axis=1)
    assert radius.min() > 1.19e7 and radius.max() < 1.25e7     # LAGEOS-2: a = 12 163 km, e = 0.014
