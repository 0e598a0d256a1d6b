"""The default Earth orientation (issue 16): the IERS table of the maintained astropy-iers-data
package, checked against an independent IERS publication (Bulletin B 274 of December 2010, in
../shared/realdata/orekit-w3b), and a warning only for dates the table does not cover."""

import warnings

import numpy as np
import pytest

from trackproc.dynamics.timescales import EopCoverageWarning
from trackproc.io.eop import earth_orientation
from realdata import W3B


def test_default_is_the_bundled_iers_table_without_warning(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("TRACKPROC_CACHE_DIR", raising=False)      # (tests/conftest.py sets one)
    eop, warning = earth_orientation()
    assert warning is None and eop.tabulated and "astropy-iers-data" in eop.source
    again, _ = earth_orientation()             # from the cache written by the first call
    assert np.array_equal(again.mjd, eop.mjd) and np.array_equal(again.ut1_minus_tai_s, eop.ut1_minus_tai_s)
    assert list(tmp_path.joinpath("trackproc").glob("*.npz"))


@pytest.mark.skipif(not W3B.is_dir(), reason="real data not available")
def test_bundled_table_matches_iers_bulletin_b_274():
    eop, _ = earth_orientation()
    rows = [line.split() for line in (W3B / "bulletinb-274.txt").read_text(errors="replace").splitlines()]
    rows = [r for r in rows if len(r) == 14 and r[0] == "2010" and r[3].isdigit()]
    # section 1 (final daily values) only: its MJDs increase; later sections repeat the dates
    end = next((i for i in range(1, len(rows)) if int(rows[i][3]) <= int(rows[i - 1][3])), len(rows))
    rows = rows[:end]
    assert len(rows) >= 20
    mjd = np.array([float(r[3]) for r in rows])
    dut1, xp, yp = eop.at(np.floor(mjd) + 2400000.5, mjd - np.floor(mjd))
    mas = np.degrees(1) * 3600e3
    # Bulletin B columns: x, y (mas), UT1-UTC (ms); C04 05 then, C04 20 in today's finals: < 0.1 ms, < 0.5 mas
    assert np.max(np.abs(dut1 * 1e3 - [float(r[6]) for r in rows])) < 0.1
    assert np.max(np.abs(xp * mas - [float(r[4]) for r in rows])) < 0.5
    assert np.max(np.abs(yp * mas - [float(r[5]) for r in rows])) < 0.5


def test_dates_beyond_the_table_are_warned_about():
    eop, _ = earth_orientation()
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        eop.at(2400000.5 + eop.mjd[-1] - 10, 0.0)
        assert not seen
        eop.at(2400000.5 + eop.mjd[-1] + 400, 0.0)
    assert any(issubclass(w.category, EopCoverageWarning) for w in seen)
