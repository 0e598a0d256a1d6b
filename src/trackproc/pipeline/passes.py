"""``trackproc passes``: the pass schedule of an orbit (state or TLE) over stations -- AOS, TCA,
LOS, maximum elevation, azimuths and Doppler at AOS/TCA/LOS (issue 18 item 5).

1. The satellite: :class:`~trackproc.pipeline.orbit_source.Satellite` (SGP4 for a TLE, the
   Taylor engine for a state), its observables by the one-way foundation model
   (:func:`~trackproc.pipeline.orbit_source.observe`: light time, WGS-84 east-north-up
   azimuth/elevation of the light-time-corrected direction, refraction neglected).
2. A coarse grid ``start + k step`` of elevations per station. Every local maximum of the grid
   brackets a maximum of the elevation curve within ``[t_{k-1}, t_{k+1}]`` (one per approach:
   the elevation of a LEO orbit has a single maximum per approach, below the horizon too), so a
   grazing pass shorter than the step is not missed. The maximum is refined by golden-section
   search; when it is at or above the mask the pass exists.
3. AOS and LOS: the last grid point below the mask before the maximum (first after it) brackets
   the crossing, refined by bisection to 1e-6 s. A pass already up at the start (still up at the
   end) has its AOS (LOS) at the span's edge and ``complete = false``.
4. TCA (closest approach): the zero of the range-rate between AOS and LOS, by bisection (empty
   when the range-rate does not change sign there, e.g. a pass cut by the span).

All refinements are vectorised over the passes of a station (one observables call per iteration).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
import pandas as pd

from trackproc import __version__
from trackproc.errors import InputError
from trackproc.io.jsonutil import json_ready
from trackproc.io.statefile import format_epoch
from trackproc.io.tle import tle_epoch
from trackproc.isotime import iso_utc
from trackproc.pipeline.orbit_source import SGP4_LABEL, Satellite, observe, resolve_force
from trackproc.io.validate import check_carrier

DEG = np.pi / 180.0
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
#: Bisection and golden-section iterations: 30 s brackets to below 1e-6 s.
BISECTIONS = 36
GOLDEN_STEPS = 50
MAX_GRID = 2_000_000


@dataclass
class PassesOptions:
    span_s: float
    step_s: float = 30.0
    start: Optional[np.datetime64] = None
    min_elevation_deg: float = 0.0
    carrier_hz: Optional[float] = None
    force: Optional[str] = None
    #: The ForceModel of ``force="full"`` (trackproc.dynamics.forces; cli.force_options builds it).
    force_model: Optional[object] = None
    earth: str = "wgs84"
    range_rate_model: str = "doppler"


def _check(options: PassesOptions) -> None:
    if not (np.isfinite(options.span_s) and options.span_s > 0):
        raise InputError("must be positive", column="--span", found=options.span_s, expected="a duration > 0")
    if not (np.isfinite(options.step_s) and 0 < options.step_s <= 300):
        raise InputError("out of range", column="--step", found=options.step_s,
                         expected="seconds in (0, 300] (longer steps could straddle a whole LEO pass)")
    if options.span_s / options.step_s > MAX_GRID:
        raise InputError("too many grid points", column="--step", found=options.step_s,
                         expected=f"at most {MAX_GRID} steps over --span")
    if not -90.0 <= options.min_elevation_deg < 90.0:
        raise InputError("out of range", column="--min-elevation", found=options.min_elevation_deg,
                         expected="degrees in [-90, 90)")
    if options.carrier_hz is not None:
        check_carrier(options.carrier_hz)


def _golden_max(f, lo, hi):
    """Maximise ``f`` (vectorised) on brackets ``[lo, hi]``: golden-section search."""
    a, b = lo.copy(), hi.copy()
    c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
    fc, fd = np.split(f(np.concatenate([c, d])), 2)        # one call: f is elementwise
    for _ in range(GOLDEN_STEPS):
        left = fc > fd                       # the maximum lies in [a, d]
        a, b = np.where(left, a, c), np.where(left, d, b)
        c_new, d_new = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
        # reuse the interior point that survives; evaluate the other one
        c, d = np.where(left, c_new, d), np.where(left, c, d_new)
        x = np.where(left, c, d)
        fx = f(x)
        fc, fd = np.where(left, fx, fd), np.where(left, fc, fx)
    return 0.5 * (a + b)


def _bisect(f, lo, hi):
    """Zero of ``f`` (vectorised) with ``f(lo)`` and ``f(hi)`` of opposite signs."""
    a, b = lo.copy(), hi.copy()
    fa = f(a)
    for _ in range(BISECTIONS):
        m = 0.5 * (a + b)
        fm = f(m)
        same = np.sign(fm) == np.sign(fa)
        a, fa, b = np.where(same, m, a), np.where(same, fm, fa), np.where(same, b, m)
    return 0.5 * (a + b)


def station_passes(sat, station, options: PassesOptions) -> list[dict]:
    """The passes of one station (dicts of :func:`find_passes`'s columns), in time order."""
    mask = options.min_elevation_deg * DEG

    def obs(t):
        return observe(sat, station, t, carrier_hz=options.carrier_hz or 1.0,
                       range_rate_model=options.range_rate_model, earth=options.earth)

    def elevation(t):
        return obs(t).elevation_rad

    n = int(math.floor(options.span_s / options.step_s * (1 + 1e-12)))
    grid = np.arange(n + 1) * options.step_s
    if grid[-1] < options.span_s:
        grid = np.append(grid, options.span_s)
    el = elevation(grid)
    k = np.arange(1, len(grid) - 1)
    peaks = k[(el[k] >= el[k - 1]) & (el[k] > el[k + 1])]
    edge_peaks = [i for i, j in ((0, 1), (len(grid) - 1, len(grid) - 2)) if el[i] > el[j] and el[i] >= mask]
    rows: list[dict] = []
    if len(peaks):
        t_max = _golden_max(elevation, grid[peaks - 1], grid[peaks + 1])
    else:
        t_max = np.zeros(0)
    t_max = np.concatenate([t_max, grid[edge_peaks]])
    if not len(t_max):
        return rows
    el_max = elevation(t_max)
    keep = el_max >= mask
    t_max, el_max = t_max[keep], el_max[keep]
    if not len(t_max):
        return rows
    # AOS bracket: the last grid point below the mask before the maximum; LOS: the first after it
    below_t = grid[el < mask]
    aos_lo = np.full(len(t_max), np.nan)
    los_hi = np.full(len(t_max), np.nan)
    k_before = np.searchsorted(below_t, t_max, side="left") - 1
    k_after = np.searchsorted(below_t, t_max, side="right")
    aos_lo[k_before >= 0] = below_t[k_before[k_before >= 0]]
    los_hi[k_after < len(below_t)] = below_t[k_after[k_after < len(below_t)]]

    def crossing(lo, hi):
        out = np.full(len(lo), np.nan)
        ok = np.isfinite(lo) & np.isfinite(hi)
        if ok.any():
            out[ok] = _bisect(lambda t: elevation(t) - mask, lo[ok], hi[ok])
        return out

    # AOS and LOS bisected together: one model call per step for both (each element's search is
    # its own: the same times as two searches)
    aos, los = np.split(crossing(np.concatenate([aos_lo, t_max]), np.concatenate([t_max, los_hi])), 2)
    aos_complete, los_complete = np.isfinite(aos), np.isfinite(los)
    aos = np.where(aos_complete, aos, 0.0)
    los = np.where(los_complete, los, grid[-1])
    # one pass per AOS (a flat top could give two grid maxima)
    _, first = np.unique(np.round(aos, 3), return_index=True)
    order = np.sort(first)
    aos, los, t_max, el_max = aos[order], los[order], t_max[order], el_max[order]
    aos_complete, los_complete = aos_complete[order], los_complete[order]
    at_aos, at_los = obs(aos), obs(los)
    tca = np.full(len(aos), np.nan)
    sign_change = (at_aos.range_rate_m_s < 0) & (at_los.range_rate_m_s > 0)
    if sign_change.any():
        tca[sign_change] = _bisect(lambda t: obs(t).range_rate_m_s, aos[sign_change], los[sign_change])
    at = {"aos": at_aos, "tca": obs(np.where(np.isfinite(tca), tca, aos)), "los": at_los}
    times = {name: sat.times(t) for name, t in (("aos", aos), ("tca", np.where(np.isfinite(tca), tca, 0.0)),
                                                 ("los", los), ("max", t_max))}
    for i in range(len(aos)):
        row = {"station": station.name, "aos_time": times["aos"][i], "tca_time": times["tca"][i] if np.isfinite(tca[i])
               else None, "los_time": times["los"][i], "duration_s": float(los[i] - aos[i]),
               "max_elevation_time": times["max"][i], "max_elevation_deg": float(el_max[i] / DEG)}
        for name in ("aos", "tca", "los"):
            o = at[name]
            have = name != "tca" or np.isfinite(tca[i])
            row[f"{name}_azimuth_deg"] = float(o.azimuth_rad[i] / DEG) if have else None
            row[f"{name}_elevation_deg"] = float(o.elevation_rad[i] / DEG) if have else None
            row[f"{name}_range_m"] = float(o.range_m[i]) if have else None
            if options.carrier_hz is not None:
                row[f"{name}_doppler_hz"] = float(o.doppler_hz[i]) if have else None
        row["complete"] = bool(aos_complete[i] and los_complete[i])
        rows.append(row)
    return rows


COLUMN_ORDER = ("station", "aos_time", "aos_azimuth_deg", "aos_elevation_deg", "aos_range_m", "aos_doppler_hz",
                "tca_time", "tca_azimuth_deg", "tca_elevation_deg", "tca_range_m", "tca_doppler_hz",
                "max_elevation_time", "max_elevation_deg",
                "los_time", "los_azimuth_deg", "los_elevation_deg", "los_range_m", "los_doppler_hz",
                "duration_s", "complete")


def find_passes(orbit, stations: dict, options: PassesOptions, eop=None):
    """The passes of ``orbit`` (:class:`~trackproc.pipeline.orbit_source.OrbitInput`) over
    ``stations`` (name -> Station): a DataFrame (columns :data:`COLUMN_ORDER`, the Doppler ones
    only with a carrier; times UTC ``datetime64``) sorted by AOS then station, and metadata."""
    _check(options)
    force = resolve_force(orbit, options.force, allow_full=options.force_model is not None)
    start = options.start
    if start is None:
        start = orbit.state.epoch if orbit.state is not None else tle_epoch(orbit.tle)
    sat = Satellite(orbit, force, start, 0.0, options.span_s, eop, force_model=options.force_model)
    rows = []
    for name in sorted(stations):
        rows.extend(station_passes(sat, stations[name], options))
    columns = [c for c in COLUMN_ORDER if options.carrier_hz is not None or not c.endswith("_doppler_hz")]
    frame = pd.DataFrame(rows, columns=columns)
    if len(frame):
        frame = frame.sort_values(["aos_time", "station"], kind="stable").reset_index(drop=True)
    meta = {
        "generator": "trackproc passes",
        "orbit": orbit.source,
        "force_model": (SGP4_LABEL if force == "sgp4" else options.force_model.label() if options.force_model is not None
                        else force),
        "start": format_epoch(start),
        "end": format_epoch(sat.times(options.span_s)[0]),
        "step_s": options.step_s,
        "min_elevation_deg": options.min_elevation_deg,
        "stations": sorted(stations),
        "definitions": ("AOS/LOS: elevation crosses --min-elevation (geometric, no refraction); TCA: range-rate "
                        "= 0 (closest approach); azimuth from north through east; one-way light time; Doppler = "
                        "received - carrier = -f range_rate / c"),
        "earth_orientation": getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)",
        "trackproc_version": __version__,
    }
    if force != "sgp4" and orbit.tle is not None:
        meta["note"] = f"TLE integrated with {force} from its SGP4 state at {format_epoch(start)}, not SGP4"
    if options.carrier_hz is not None:
        meta["carrier_hz"] = options.carrier_hz
    return frame, meta


FORMATS = ("csv", "json", "md")


def _cell(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (np.datetime64, pd.Timestamp)):
        return format_epoch(np.datetime64(value, "ns"))
    if isinstance(value, (float, np.floating)):
        return f"{round(float(value), digits) + 0.0:.{digits}f}"     # + 0.0: no "-0.000"
    return str(value)


def render(frame: pd.DataFrame, meta: dict, fmt: str) -> str:
    """The schedule as CSV (a header, one row per pass, ISO 8601 UTC times), JSON
    (``{"meta": ..., "passes": [...]}``) or a Markdown table (one line per pass, the times to 0.01 s)."""
    records = frame.to_dict("records")
    if fmt == "json":
        def value(v):
            if v is None or (not isinstance(v, str) and pd.isna(v)):
                return None
            return _cell(v) if isinstance(v, (np.datetime64, pd.Timestamp)) else v

        passes = [{k: value(v) for k, v in r.items()} for r in records]
        return json.dumps(json_ready({"meta": meta, "passes": passes}), indent=2) + "\n"
    if fmt == "csv":
        lines = [",".join(frame.columns)]
        lines += [",".join(_cell(r[c], 6 if c.endswith(("_doppler_hz", "_deg")) else 3) for c in frame.columns)
                  for r in records]
        return "\n".join(lines) + "\n"
    if fmt == "md":
        doppler = "aos_doppler_hz" in frame.columns
        head = ["station", "AOS (UTC)", "az", "TCA (UTC)", "max el", "az", "LOS (UTC)", "az", "minutes"]
        if doppler:
            head += ["Doppler AOS/TCA/LOS (Hz)"]
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

        def hms(t):     # rounded to 0.01 s, as the JSON's times read to a person
            if t is None or pd.isna(t):
                return ""
            stamp = pd.Timestamp(t)
            stamp = stamp.tz_convert(None) if stamp.tzinfo is not None else stamp
            return iso_utc(stamp.round("10ms"), 2, suffix="").replace("T", " ")

        for r in records:
            cells = [r["station"], hms(r["aos_time"]), _cell(r["aos_azimuth_deg"], 1), hms(r["tca_time"]),
                     _cell(r["max_elevation_deg"], 1), _cell(r["tca_azimuth_deg"], 1), hms(r["los_time"]),
                     _cell(r["los_azimuth_deg"], 1), _cell(r["duration_s"] / 60.0, 1)]
            if doppler:
                cells.append(" / ".join(f"{v:+.0f}" if v is not None and math.isfinite(v) else "-"
                                        for v in (r["aos_doppler_hz"], r["tca_doppler_hz"], r["los_doppler_hz"])))
            if not r["complete"]:
                cells[0] += " (cut by the span)"
            lines.append("| " + " | ".join(cells) + " |")
        title = (f"Passes of {meta['orbit']} above {meta['min_elevation_deg']:g} deg, {meta['start']} .. "
                 f"{meta['end']} ({meta['force_model'].split(' (')[0]})")
        return f"{title}\n\n" + "\n".join(lines) + "\n"
    raise InputError("unknown format", column="--format", found=fmt, expected=", ".join(FORMATS))
