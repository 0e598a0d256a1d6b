"""``trackproc refine`` on real DopTrack Delfi-C3 passes (../shared/realdata; skipped when absent).

Each pass is refined from the TLE of its own metadata (SGP4 at the traverse epoch, the default
a-priori of a state without covariance, per-pass offset and drift); the refined state is then
propagated to the NEXT pass (about 95 minutes later) and its range-rate compared with the data,
beside the TLE's own prediction. Both residual RMS are taken after that pass's own frequency
offset and drift (fitted, 4-sigma editing), which no orbit can predict.
"""

from __future__ import annotations

import datetime as dt
import json

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics import frames
from trackproc.dynamics import timescales as ts
from trackproc.io.tle import parse_tle, sgp4_teme, tle_state
from trackproc.models import observation as ob
from trackproc.pipeline.estimate import EstimateOptions, build_problem
from trackproc.pipeline.refine import LOW_PASS_DEG, RefineOptions, refine
from realdata import DOPTRACK, requires


pytestmark = requires(DOPTRACK)

#: UT1-UTC for April 2020 (IERS Bulletin A: about -0.2 s).
EOP = ts.EarthOrientation.constant(-0.2)
#: Consecutive passes at most this far apart form a (pass, next pass) pair.
MAX_PAIR_GAP_S = 4 * 3600.0


def _load(stamp):
    import yaml

    from trackproc.io.tabular import read_raw
    from trackproc.pipeline.ingest import ingest

    table = ingest([read_raw(str(DOPTRACK / "data" / f"Delfi-C3_32789_{stamp}.csv"))]).table
    doc = yaml.safe_load((DOPTRACK / "metadata" / f"Delfi-C3_32789_{stamp}.yml").read_text())
    return table, parse_tle(doc["satellite"]["tle"]["line1"] + "\n" + doc["satellite"]["tle"]["line2"])


class _Sgp4Trajectory:
    """GCRF states of a TLE by SGP4 at seconds from an epoch (derivative by central differences)."""

    def __init__(self, tle, epoch_jd):
        self.tle, self.jd = tle, epoch_jd

    def _at(self, t):
        jd1, jd2 = ts.add_seconds_utc(self.jd, np.asarray(t, float))
        r, v = sgp4_teme(self.tle, jd1, jd2)
        r, v = frames.teme_to_gcrf(r, v, jd1, jd2, EOP)
        return np.concatenate([r, v], -1)

    def state(self, t, derivative=0):
        if derivative == 0:
            return self._at(t)
        return self._at(np.asarray(t) + 0.5) - self._at(np.asarray(t) - 0.5)


def _rms_after_own_offset_drift(t_s, residual):
    """RMS (Hz) after the pass's own offset and drift (straight-line fit, 4-sigma editing)."""
    t = t_s - t_s.min()
    keep = np.ones(t.size, bool)
    for _ in range(5):
        c = np.polyfit(t[keep], residual[keep], 1)
        r = residual - np.polyval(c, t)
        keep = np.abs(r) < 4 * max(1.0, float(np.sqrt(np.mean(r[keep] ** 2))))
    return float(np.sqrt(np.mean(r[keep] ** 2)))


def _predicted_rms(table, state, tle=None):
    """The next pass's Doppler residual RMS predicted by ``state`` (propagated by the Taylor
    engine, J2) or by the ``tle`` (SGP4)."""
    pb = build_problem([("next", table)], state, None, EstimateOptions(kinds=["doppler"]), EOP)
    meas = pb.meas
    if tle is None:
        computed, _ = pb.model(pb.x0)
    else:
        geo = ob.solve_light_time(_Sgp4Trajectory(tle, tuple(float(a) for a in ts.datetime64_to_jd_utc(pb.epoch))),
                                  meas.t_s, meas.r_st)
        rr = ob.range_rate_value(geo.state[:, :3], geo.state[:, 3:], meas.r_st, meas.v_st, pb.range_rate_model)
        computed = -meas.carrier_hz * rr / C_LIGHT
    return _rms_after_own_offset_drift(meas.t_s, meas.observed - computed)


def _pairs():
    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    out = []
    for a, b in zip(stamps[:-1], stamps[1:]):
        gap = (dt.datetime.strptime(b, "%Y%m%d%H%M") - dt.datetime.strptime(a, "%Y%m%d%H%M")).total_seconds()
        if gap <= MAX_PAIR_GAP_S:
            out.append((a, b))
    return out


def test_doptrack_refined_state_predicts_the_next_pass_better_than_the_tle():
    rows = []
    for a, b in _pairs():
        table_a, tle = _load(a)
        table_b, _ = _load(b)
        res = refine(table_a, tle_state(tle, eop=EOP), None, RefineOptions(doppler_bias="offset+drift"), EOP, source=a)
        d = res.state.diagnostics
        rows.append({"pass": a, "next": b, "max_elevation_deg": round(d["max_elevation_deg"], 1),
                     "tle_hz": round(_predicted_rms(table_b, res.state, tle), 2),
                     "refined_hz": round(_predicted_rms(table_b, res.state), 2),
                     "low_pass_warning": any("a low pass" in w for w in res.warnings)})
    print("DopTrack next-pass Doppler RMS (Hz), TLE vs refined:\n" + "\n".join(json.dumps(r) for r in rows))
    assert len(rows) >= 15
    high = [r for r in rows if r["max_elevation_deg"] >= LOW_PASS_DEG]
    low = [r for r in rows if r["max_elevation_deg"] < LOW_PASS_DEG]
    assert len(high) >= 8
    # every pass high enough to determine the orbit improves the next pass's prediction
    assert all(r["refined_hz"] < r["tle_hz"] for r in high), high
    assert np.median([r["refined_hz"] for r in high]) < 0.9 * np.median([r["tle_hz"] for r in high])
    # a low pass is said to be one
    assert all(r["low_pass_warning"] for r in low) and not any(r["low_pass_warning"] for r in high)
