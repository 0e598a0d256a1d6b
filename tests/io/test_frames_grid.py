"""Precession-nutation on a grid (issue 19): Q = GCRS -> CIRS interpolated from a 30-minute grid
against the direct ``erfa.c2i06a`` at every date, and its rate against a central difference of
the direct evaluation; the interpolated value does not depend on the other dates asked for; an EOP file is parsed once
per process and file version."""

import erfa
import numpy as np

from trackproc.dynamics import frames


def _dates(n, seed=1):
    rng = np.random.default_rng(seed)
    return rng.uniform(7000.0, 10000.0, n)           # days since J2000 TT, 2019-2027


def test_q_matches_direct_erfa_to_rounding():
    t = _dates(2000)
    q, _ = frames.precession_nutation(2451545.0, t)
    direct = np.asarray(erfa.c2i06a(2451545.0, t))
    err = np.abs(q - direct).max()
    # < 1e-15 rad: 7 nm at 7000 km, far below the 1 mm the issue allows
    assert err < 1e-15, err


def test_q_rate_matches_central_difference_of_direct_erfa():
    t = _dates(500, seed=2)
    _, q_dot = frames.precession_nutation(2451545.0, t)
    d = 60.0 / 86400.0
    ref = (np.asarray(erfa.c2i06a(2451545.0, t + d)) - np.asarray(erfa.c2i06a(2451545.0, t - d))) / 120.0
    rel = np.abs(q_dot - ref).max() / np.abs(ref).max()
    assert rel < 1e-6, rel


def test_q_independent_of_the_other_dates_and_the_cache():
    t = _dates(50, seed=3)
    alone = np.stack([frames.precession_nutation(2451545.0, np.array([x]))[0][0] for x in t[:5]])
    frames._Q_NODES.clear()
    together, _ = frames.precession_nutation(2451545.0, t)
    assert np.array_equal(alone, together[:5])


def test_q_of_a_pass_and_of_a_day_read_by_span_as_by_sorting():
    # a pass (1 s for 15 min) and a day of passes: the nodes read by their offset in the span
    # (frames._Q_SPAN_NODES), bit for bit the values of dates asked for one at a time, and the direct
    # ERFA evaluation to rounding
    rng = np.random.default_rng(4)
    for t in (8100.25 + np.arange(900) / 86400.0, np.sort(8200.0 + rng.uniform(0.0, 0.98, 300))):
        frames._Q_NODES.clear()
        q, q_dot = frames.precession_nutation(2451545.0, t)
        frames._Q_NODES.clear()
        for i in range(0, t.size, 97):
            one, one_dot = frames.precession_nutation(2451545.0, t[i:i + 1])
            assert np.array_equal(one[0], q[i]) and np.array_equal(one_dot[0], q_dot[i])
        assert np.abs(q - np.asarray(erfa.c2i06a(2451545.0, t))).max() < 1e-15


def test_earth_rotation_position_within_a_millimetre_of_direct_c2t06a():
    # the full GCRF -> ITRF matrix against erfa's one-call c2t06a at many dates of a day
    from trackproc.dynamics import timescales as ts

    j1 = np.full(300, 2461119.5)
    j2 = np.linspace(0.0, 1.0, 300)
    rot = frames.earth_rotation(j1, j2, rates=False)
    tt1, tt2 = ts.utc_to_tt(j1, j2)
    u1, u2 = ts.utc_to_ut1(j1, j2, np.zeros(300))
    expected = np.asarray(erfa.c2t06a(tt1, tt2, u1, u2, np.zeros(300), np.zeros(300)))
    r = np.array([3774841.0, -1538034.0, 5924146.0]) * 1.1        # an orbit-radius point
    assert np.abs((rot.matrix - expected) @ r).max() < 1e-3 * 1e-3   # < 1 um


def test_eop_file_parsed_once_per_version(tmp_path):
    """A batch worker reads its EOP file once (issue 19); a changed file is read again."""
    import os

    from test_eop import row
    from trackproc.io.eop import read_finals2000a

    path = tmp_path / "finals2000A.data"
    path.write_text("\n".join([row(58849, 0.1, 0.2, -0.17), row(58850, 0.1, 0.2, -0.171)]) + "\n")
    first = read_finals2000a(path)
    assert read_finals2000a(str(path)) is first
    assert not first.mjd.flags.writeable
    path.write_text("\n".join([row(58849, 0.1, 0.2, -0.17), row(58850, 0.1, 0.2, -0.171),
                               row(58851, 0.1, 0.2, -0.172)]) + "\n")
    os.utime(path, ns=(1, 1))                       # a different version even on a coarse clock
    second = read_finals2000a(path)
    assert second is not first and second.mjd.tolist() == [58849.0, 58850.0, 58851.0]
