"""IERS finals2000A reading: column positions, Bulletin A vs B, the --eop/--dut1 options."""

import numpy as np
import pytest

from trackproc.errors import InputError
from trackproc.io.eop import NO_EOP_WARNING, earth_orientation, read_finals2000a


def row(mjd, xa, ya, dut1a, b=None):
    """One finals2000A row built column by column from the IERS format description."""
    y, m, d = 20, 1, 1 + int(mjd - 58849)
    line = f"{y:2d}{m:2d}{d:2d} {mjd:8.2f} I {xa:9.6f} 0.000010 {ya:9.6f} 0.000010  I{dut1a:10.7f} 0.0000010"
    line = line.ljust(134)
    if b is not None:
        xb, yb, dut1b = b
        line += f"{xb:10.6f}{yb:10.6f}{dut1b:11.7f}"
    return line


def test_columns_and_bulletin_b_preferred(tmp_path):
    path = tmp_path / "finals2000A.data"
    path.write_text("\n".join([
        row(58849, 0.1, 0.2, -0.17),                            # A only
        row(58850, 0.1, 0.2, -0.17, b=(0.11, 0.21, -0.171)),     # B present: B wins
        row(58851, 0.1, 0.2, -0.17),
        "20 1 4 58852.00 P  0.100000 0.000010  0.200000 0.000010  P",  # no UT1: skipped
    ]) + "\n")
    eop = read_finals2000a(path)
    assert eop.mjd.tolist() == [58849.0, 58850.0, 58851.0]
    dut1, xp, yp = eop.at(np.array([2458849.5, 2458850.5]), np.array([0.0, 0.0]))
    as2r = np.pi / 180 / 3600
    np.testing.assert_allclose(dut1, [-0.17, -0.171], atol=1e-12)
    np.testing.assert_allclose(xp / as2r, [0.1, 0.11], atol=1e-12)
    np.testing.assert_allclose(yp / as2r, [0.2, 0.21], atol=1e-12)
    # linear in between (in UT1-TAI: no leap second here, so also in UT1-UTC)
    mid, _, _ = eop.at(2458850.0, 0.0)
    assert mid[()] == pytest.approx(-0.1705, abs=1e-12)


def test_bad_rows_and_options_are_input_errors(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text(row(58849, 0.1, 0.2, -0.17)[:58] + "not-a-number" + "\n")
    with pytest.raises(InputError, match="row 1"):
        read_finals2000a(bad)
    with pytest.raises(InputError, match="not found"):
        read_finals2000a(tmp_path / "missing")
    with pytest.raises(InputError, match="either --eop or --dut1"):
        earth_orientation(bad, 0.1)
    with pytest.raises(InputError, match="0.9"):
        earth_orientation(None, 1.5)
    eop, warning = earth_orientation(None, None)     # the bundled IERS table (tests/io/test_eop_bundled.py)
    assert warning is None and eop.tabulated
    eop, warning = earth_orientation(None, -0.2)
    assert warning is None and eop.at(2458850.5, 0.0)[0] == pytest.approx(-0.2)
