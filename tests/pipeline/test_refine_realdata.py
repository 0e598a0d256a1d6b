"""``trackproc refine`` on real DopTrack Delfi-C3 passes (../shared/realdata; skipped when absent).

Each pass is refined from the TLE of its own metadata (SGP4 at the traverse epoch, the default
a-priori of a state without covariance, per-pass offset and drift); the refined state is then
propagated to the NEXT pass (about 95 minutes later) and its range-rate compared with the data,
beside the TLE's own prediction. Both residual RMS are taken after that pass's own frequency
offset and drift (fitted, 4-sigma editing), which no orbit can predict.
"""

from __future__ import annotations

import copy
import datetime as dt
from dataclasses import dataclass
from functools import lru_cache
import json

import numpy as np
import pytest

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
    """The pass ``stamp`` ingested and the TLE of its metadata. Each file is read once per process
    (the realdata tests and benchmarks read the same passes many times over); every caller gets a
    table of its own to change."""
    table = _ingested(stamp)
    return type(table)(table.frame.copy(), copy.deepcopy(table.meta)), metadata_tle_of(stamp)


@lru_cache(maxsize=None)
def _ingested(stamp):
    from trackproc.io.tabular import read_raw
    from trackproc.pipeline.ingest import ingest

    return ingest([read_raw(str(DOPTRACK / "data" / f"Delfi-C3_32789_{stamp}.csv"))]).table


@lru_cache(maxsize=None)
def metadata_tle_of(stamp):
    """The TLE in the metadata of pass ``stamp`` (its CSV not read)."""
    import yaml

    doc = yaml.safe_load((DOPTRACK / "metadata" / f"Delfi-C3_32789_{stamp}.yml").read_text())
    return parse_tle(doc["satellite"]["tle"]["line1"] + "\n" + doc["satellite"]["tle"]["line2"])


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
    return _fit_after_own_offset_drift(t_s, residual)[0]


def _fit_after_own_offset_drift(t_s, residual, *extra, sigmas=False):
    """``(rms, coefficients of extra)``: the RMS (Hz) after the pass's own offset and drift and
    the ``extra`` columns fitted together (least squares, 4-sigma editing); with ``sigmas`` also
    the coefficients' formal sigmas (from that RMS)."""
    t = t_s - t_s.min()
    a = np.column_stack([np.ones_like(t), t, *extra])
    keep = np.ones(t.size, bool)
    for _ in range(5):
        c = np.linalg.lstsq(a[keep], residual[keep], rcond=None)[0]
        r = residual - a @ c
        rms = float(np.sqrt(np.mean(r[keep] ** 2)))
        keep = np.abs(r) < 4 * max(1.0, rms)
    rms = float(np.sqrt(np.mean(r[keep] ** 2)))
    if not sigmas:
        return rms, c[2:]
    return rms, c[2:], rms * np.sqrt(np.diag(np.linalg.inv(a[keep].T @ a[keep])))[2:]


def _rate(t_s, computed):
    """The modelled observable's rate (per second) at each sample, any order."""
    order = np.argsort(t_s)
    rate = np.empty_like(computed)
    rate[order] = np.gradient(computed[order], t_s[order])
    return rate


def timing_split(table, state, tle=None):
    """The part of a pass's predicted Doppler error that is timing: ``(rms, rms_after_shift,
    shift_s)``: the RMS after the pass's own offset and drift, then also after the best time
    shift of the prediction (positive when the satellite passes later than predicted, fit-tle's
    convention), and that shift. An along-track error of the orbit and a time-tag error of the
    station look the same here."""
    t_s, residual, computed = _predicted_residuals(table, state, tle)
    rms_after, (c,) = _fit_after_own_offset_drift(t_s, residual, _rate(t_s, computed))
    return _rms_after_own_offset_drift(t_s, residual), rms_after, -float(c)


def _predicted_rms(table, state, tle=None):
    """The next pass's Doppler residual RMS predicted by ``state`` (propagated by the Taylor
    engine, J2) or by the ``tle`` (SGP4)."""
    t_s, residual, _ = _predicted_residuals(table, state, tle)
    return _rms_after_own_offset_drift(t_s, residual)


def _predicted_residuals(table, state, tle=None):
    """``(t_s, observed - computed, computed)`` (Hz) of a pass's Doppler samples predicted by
    ``state`` (Taylor, J2) or by the ``tle`` (SGP4)."""
    pb = build_problem([("next", table)], state, None, EstimateOptions(kinds=["doppler"]), EOP)
    meas = pb.meas
    if tle is None:
        computed, _ = pb.model(pb.x0)
    else:
        geo = ob.solve_light_time(_Sgp4Trajectory(tle, tuple(float(a) for a in ts.datetime64_to_jd_utc(pb.epoch))),
                                  meas.t_s, meas.r_st)
        rr = ob.range_rate_value(geo.state[:, :3], geo.state[:, 3:], meas.r_st, meas.v_st, pb.range_rate_model)
        computed = -meas.carrier_hz * rr / C_LIGHT
    return meas.t_s, meas.observed - computed, computed


def time_shift_and_sigma(table, state, tle=None):
    """The best time shift of the prediction (s, :func:`timing_split`'s) and its formal sigma (the
    least-squares sigma of the shift coefficient, with the offset and drift, from the RMS after)."""
    t_s, residual, computed = _predicted_residuals(table, state, tle)
    _, (c,), (sigma,) = _fit_after_own_offset_drift(t_s, residual, _rate(t_s, computed), sigmas=True)
    return -float(c), float(sigma)


def station_time_sigma(shifts, formal, centre=0.0, k=3.0):
    """The time-tag sigma of a station from its passes' time shifts against fresh TLEs (a fresh TLE
    is good to ~0.05 s along-track): the maximum-likelihood ``σ`` of ``shift_i ~ N(centre, σ² +
    formal_i²)``, passes beyond ``k`` σ left out and the fit repeated until the set is stable.
    Returns ``(σ, kept mask)``."""
    from scipy.optimize import minimize_scalar

    shifts, formal = np.asarray(shifts, float), np.asarray(formal, float)
    keep = np.ones(shifts.size, bool)
    for _ in range(20):
        def nll(sig, m=keep):
            v = sig ** 2 + formal[m] ** 2
            return 0.5 * float(np.sum(np.log(v) + (shifts[m] - centre) ** 2 / v))
        sigma = float(minimize_scalar(nll, bounds=(1e-4, 30.0), method="bounded").x)
        new = np.abs(shifts - centre) < k * np.sqrt(sigma ** 2 + formal ** 2)
        if (new == keep).all():
            break
        keep = new
    return sigma, keep


def doptrack_time_shifts(dev: bool):
    """``[(stamp, shift s, formal sigma s)]`` of every good pass of the development (or hold-out)
    days against its own TLE (SGP4)."""
    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    out = []
    for s in stamps:
        if is_dev(s) != dev or s in BAD_PASSES:
            continue
        table, tle = _load(s)
        out.append((s, *time_shift_and_sigma(table, tle_state(tle, eop=EOP), tle)))
    return out


def _pairs():
    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    out = []
    for a, b in zip(stamps[:-1], stamps[1:]):
        gap = (dt.datetime.strptime(b, "%Y%m%d%H%M") - dt.datetime.strptime(a, "%Y%m%d%H%M")).total_seconds()
        if gap <= MAX_PAIR_GAP_S:
            out.append((a, b))
    return out


#: The development passes (1-10 April 2020); 11-15 April is the hold-out, evaluated only by
#: benchmarks/doptrack_prediction.py and reported in docs/refine.md.
LAST_DEV_DAY = "20200410"
#: The pass the data README calls bad (hundreds of m/s).
BAD_PASSES = ("202004011959",)


def is_dev(stamp: str) -> bool:
    return stamp[:8] <= LAST_DEV_DAY


def evenings():
    """Groups of at least two consecutive passes, each within :data:`MAX_PAIR_GAP_S` of the previous."""
    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    groups, cur = [], []
    for s in stamps:
        if s in BAD_PASSES:
            continue
        if cur and (dt.datetime.strptime(s, "%Y%m%d%H%M")
                    - dt.datetime.strptime(cur[-1], "%Y%m%d%H%M")).total_seconds() > MAX_PAIR_GAP_S:
            groups.append(cur)
            cur = []
        cur.append(s)
    groups.append(cur)
    return [g for g in groups if len(g) >= 2]


@dataclass(frozen=True)
class HeldBack:
    """An evening for a held-back test: ``passes`` ``[(stamp, table)]`` fitted, the ``held``-back
    last pass's table, the ``tle`` of the first pass and the ``initial`` state: that TLE at the
    first fitted sample, with refine's default a-priori covariance for a state without one."""

    passes: list
    held: object
    tle: object
    initial: object


def held_back(group) -> HeldBack:
    """:class:`HeldBack` of the evening ``group`` (its passes' stamps, in time order)."""
    from trackproc.constants import MU_EARTH
    from trackproc.io.statefile import State
    from trackproc.pipeline.refine import default_apriori_covariance

    fit, held = group[:-1], group[-1]
    loaded = [_load(s) for s in fit]
    table_b, _ = _load(held)
    tle = loaded[0][1]
    first = min(t.frame["time"].min() for t, _ in loaded).tz_convert("UTC").tz_localize(None).to_datetime64()
    st = tle_state(tle, at=first, eop=EOP)
    initial = State.from_vectors(st.epoch, st.r_m, st.v_m_s,
                                 covariance=default_apriori_covariance(np.r_[st.r_m, st.v_m_s], MU_EARTH))
    return HeldBack(passes=[(s, t) for s, (t, _) in zip(fit, loaded)], held=table_b, tle=tle, initial=initial)


def estimate_held_back(group, noise="auto"):
    """``estimate`` over every pass of ``group`` but the last (the TLE of the first at its first
    sample, with the default a-priori covariance of ``refine`` for a state without one, as a
    state file with that covariance and --apriori-initial; offset and drift per pass), and the
    held-back last pass's Doppler RMS predicted by it and by the TLE. Returns ``(tle Hz, ours Hz,
    EstimateResult)``."""
    from trackproc.pipeline.estimate import estimate

    hb = held_back(group)
    opts = EstimateOptions(doppler_bias="offset+drift", epoch="first", apriori_initial=True, noise=noise)
    res = estimate(hb.passes, hb.initial, None, opts, EOP)
    return _predicted_rms(hb.held, res.state, hb.tle), _predicted_rms(hb.held, res.state), res


def _next_pass_rows(pairs, bias=None):
    rows = []
    for a, b in pairs:
        table_a, tle = _load(a)
        table_b, _ = _load(b)
        res = refine(table_a, tle_state(tle, eop=EOP), None, RefineOptions(doppler_bias=bias), EOP, source=a)
        d = res.state.diagnostics
        tle_hz, refined_hz = _predicted_rms(table_b, res.state, tle), _predicted_rms(table_b, res.state)
        rows.append({"pass": a, "next": b, "max_elevation_deg": round(d["max_elevation_deg"], 1),
                     "tle_hz": round(tle_hz, 2), "refined_hz": round(refined_hz, 2),
                     # a refusal keeps the TLE's state: it counts as equal (the Taylor propagation of the
                     # kept SGP4 state differs from SGP4 itself by ~1 %)
                     "ratio": 1.0 if d["refused"] else round(refined_hz / tle_hz, 3),
                     "refused": (d["refused"] or {}).get("code"), "quality": res.quality.verdict,
                     "noise": d["noise"]["model"], "transmitter": d["noise"]["transmitter"],
                     "low_pass_warning": any("a low pass" in w for w in res.warnings)})
    print(f"DopTrack next-pass Doppler RMS (Hz), TLE vs refined (--doppler-bias {bias or 'default'}):\n"
          + "\n".join(json.dumps(r) for r in rows))
    return rows


def test_doptrack_refine_predicts_the_next_pass_no_worse_than_the_tle():
    """Never worse than the TLE the user had, on the development pairs (1-10 April) with the
    defaults (noise model and drift by REML, GLS, the TLE's stated accuracy as the a-priori, the
    replace/keep/decline rule of methods/estimation/decision.py): every pair within 1.10x of the
    TLE's next-pass RMS and none beyond 2x; a kept or declined TLE counts as the TLE's answer. A
    pass that contradicts its TLE is declined (suspect); one whose refinement would not predict
    better is kept (the TLE is the answer). (Before the rule, single passes moved the TLE by their
    own timing errors: median 0.91 here by chance, 21-36x worse on unseen days.)"""
    rows = _next_pass_rows([(a, b) for a, b in _pairs() if is_dev(a)])
    assert len(rows) >= 7
    ratio = np.array([r["ratio"] for r in rows])
    assert (ratio <= 1.1).all() and ratio.max() <= 2.0, rows
    assert all(r["quality"] == "suspect" for r in rows if r["refused"] in ("declined", "refused")), rows
    # a low pass is said to be one
    assert all(r["low_pass_warning"] == (r["max_elevation_deg"] < LOW_PASS_DEG) for r in rows)


@pytest.mark.slow
def test_doptrack_station_timing_is_the_one_its_adapter_states():
    """The DopTrack station's time-tag sigma that io/doptrack.py states (refine's consider term) is
    the one its development passes show against their own fresh TLEs (SGP4, an independent orbit):
    recomputed here by maximum likelihood, within 10 %, from at least 20 passes; and its tags are
    not exact (a GPS clock's microseconds would make every shift a few formal sigmas)."""
    from trackproc.io.doptrack import KNOWN_STATION_TIME_SIGMA_S

    rows = doptrack_time_shifts(dev=True)
    shifts, formal = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
    sigma, keep = station_time_sigma(shifts, formal)
    print("DopTrack time shifts (s):", [(r[0], round(r[1], 3), round(r[2], 3)) for r in rows], "sigma", sigma)
    assert keep.sum() >= 20
    assert abs(sigma - KNOWN_STATION_TIME_SIGMA_S["doptrack"]) <= 0.1 * sigma
    assert np.median(np.abs(shifts) / formal) > 10.0


def test_doptrack_estimate_predicts_a_held_back_pass_within_1_2x_the_tle():
    """Issue 13's criterion on the development evenings: every pass but the last estimated
    together, the last held back and predicted no worse than 1.2x the TLE."""
    rows = []
    for group in evenings():
        if not is_dev(group[0]):
            continue
        tle_hz, ours, res = estimate_held_back(group)
        rows.append((group, round(tle_hz, 2), round(ours, 2)))
    print("DopTrack held-back pass (Hz), TLE vs estimate:", rows)
    assert len(rows) >= 6
    assert all(o <= 1.2 * t for _, t, o in rows), rows
