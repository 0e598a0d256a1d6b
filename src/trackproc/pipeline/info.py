"""Summary of a pass file (``trackproc info``): stations, passes, kinds, carrier and mode.

:func:`summarize` returns a :class:`PassFileInfo`; :func:`info_dict` gives its JSON form and
:func:`format_info` a plain aligned text table for people. Times are UTC ISO 8601 with ``Z``,
durations in seconds, elevations in degrees.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from trackproc.constants import MU_EARTH, WGS84_A
from trackproc.dynamics.kepler import classical_elements
from trackproc.io.opm import parse_opm
from trackproc.io.passfile import COLUMNS, KINDS, PassTable, iso_times
from trackproc.io.statefile import format_epoch, parse_state
from trackproc.io.tdm import read_tdm
from trackproc.io.tle import parse_tle, tle_epoch
from trackproc.isotime import iso_utc
from trackproc.pipeline.numbers import format_number
from trackproc.vocabulary import BIAS_UNITS, CONSTRAINT_PARAMETERS, FORCE_PARAMETERS


@dataclass
class PassInfo:
    pass_id: str
    station: str
    start: str
    end: str
    duration_s: float
    samples: dict[str, int]                 # kind -> number of samples
    max_elevation_deg: float | None = None  # when the pass has elevation samples


@dataclass
class StationInfo:
    name: str
    lat_deg: float | None
    lon_deg: float | None
    height_m: float | None
    passes: int
    samples: int


@dataclass
class PassFileInfo:
    source: str
    samples: int
    start: str | None
    end: str | None
    kinds: dict[str, int]
    stations: list[StationInfo]
    passes: list[PassInfo]
    carrier_hz: float | None = None
    doppler_mode: str | None = None
    schema_version: int | None = None
    time_scale: str | None = None
    sources: list[str] = field(default_factory=list)
    dropped_rows: dict[str, int] = field(default_factory=dict)
    extra_columns: list[str] = field(default_factory=list)
    trackproc_version: str | None = None


def summarize(table: PassTable, source: str) -> PassFileInfo:
    """Counts per kind, station and pass; pass start/end/duration; max elevation per pass."""
    frame, meta = table.frame.reset_index(drop=True), table.meta
    iso = iso_times(frame["time"]) if len(frame) else np.array([], dtype=str)
    kinds = {k: int(n) for k, n in frame["kind"].value_counts().items()}
    kinds = {k: kinds[k] for k in [*KINDS, *sorted(set(kinds) - set(KINDS))] if k in kinds}
    passes = []
    for (station, pass_id), group in frame.groupby(["station", "pass_id"], sort=False):
        first, last = group["time"].idxmin(), group["time"].idxmax()
        start, end = frame["time"].iat[first], frame["time"].iat[last]
        counts = group["kind"].value_counts()
        elevation = group.loc[group["kind"] == "elevation", "value"]
        passes.append(PassInfo(
            pass_id=str(pass_id), station=str(station), start=str(iso[first]), end=str(iso[last]),
            duration_s=(end - start).total_seconds(),
            samples={k: int(counts[k]) for k in kinds if k in counts},
            max_elevation_deg=float(np.degrees(elevation.max())) if len(elevation) else None,
        ))
    passes.sort(key=lambda p: (p.station, p.start, p.pass_id))
    known = meta.get("stations") or {}
    stations = []
    for name in sorted(frame["station"].unique()):
        coords = known.get(name) or {}
        stations.append(StationInfo(
            name=str(name), lat_deg=coords.get("lat_deg"), lon_deg=coords.get("lon_deg"),
            height_m=coords.get("height_m"), passes=sum(p.station == name for p in passes),
            samples=int((frame["station"] == name).sum())))
    span = ([str(iso[frame["time"].idxmin()]), str(iso[frame["time"].idxmax()])] if len(frame)
            else [None, None])
    return PassFileInfo(
        source=source, samples=len(frame), start=span[0], end=span[1], kinds=kinds,
        stations=stations, passes=passes, carrier_hz=meta.get("carrier_hz"),
        doppler_mode=meta.get("doppler_mode"), schema_version=meta.get("schema_version"),
        time_scale=meta.get("time_scale"), sources=list(meta.get("sources") or []),
        dropped_rows=dict(meta.get("dropped_rows") or {}),
        extra_columns=[c for c in frame.columns if c not in COLUMNS],
        trackproc_version=meta.get("trackproc_version"),
    )


def info_dict(info: PassFileInfo) -> dict:
    """JSON-ready form of the summary."""
    return asdict(info)


def _number(value, digits: int) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


def _table(headers: list[str], rows: list[list[str]], right: set[int]) -> list[str]:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells):
        return "  ".join(c.rjust(w) if i in right else c.ljust(w)
                         for i, (c, w) in enumerate(zip(cells, widths))).rstrip()

    return [line(headers)] + [line(r) for r in rows]


def format_info(info: PassFileInfo) -> str:
    """A plain, aligned text summary for people."""
    lines = [f"file        {info.source}"]
    if info.sources:
        lines.append(f"sources     {', '.join(info.sources)}")
    lines.append(f"samples     {info.samples}  ("
                 + ", ".join(f"{k} {n}" for k, n in info.kinds.items()) + ")")
    if info.start:
        lines.append(f"time span   {info.start} .. {info.end}  ({info.time_scale or 'UTC'})")
    carrier = f"{info.carrier_hz:.1f} Hz" if info.carrier_hz is not None else "-"
    lines.append(f"carrier     {carrier}, Doppler mode {info.doppler_mode or '-'}")
    if info.dropped_rows:
        lines.append("dropped     " + ", ".join(f"{reason} {n}" for reason, n in info.dropped_rows.items()))
    if info.extra_columns:
        lines.append("columns +   " + ", ".join(info.extra_columns))
    lines.append("")
    lines += _table(
        ["station", "lat_deg", "lon_deg", "height_m", "passes", "samples"],
        [[s.name, _number(s.lat_deg, 6), _number(s.lon_deg, 6), _number(s.height_m, 1), str(s.passes),
          str(s.samples)] for s in info.stations],
        right={1, 2, 3, 4, 5})
    lines.append("")
    kinds = list(info.kinds)
    has_elevation = any(p.max_elevation_deg is not None for p in info.passes)
    headers = ["pass_id", "station", "start", "end", "duration_s", *kinds]
    headers += ["max_elev_deg"] if has_elevation else []
    rows = []
    for p in info.passes:
        row = [p.pass_id, p.station, p.start, p.end, _number(p.duration_s, 1),
               *(str(p.samples.get(k, 0)) for k in kinds)]
        if has_elevation:
            row.append(_number(p.max_elevation_deg, 2))
        rows.append(row)
    lines += _table(headers, rows, right=set(range(4, len(headers))))
    return "\n".join(lines) + "\n"


def ephemeris_info(frame, meta: dict, source: str) -> dict:
    """Summary of an ephemeris table: span, samples, step, geocentric radius, height above the
    equatorial radius (a quick check, not a geodetic height) and speed ranges."""
    times = frame["time"]
    r = np.linalg.norm(frame[["x_m", "y_m", "z_m"]].to_numpy(float), axis=1)
    v = np.linalg.norm(frame[["vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy(float), axis=1)
    steps = np.diff(times.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy().astype(np.int64)) / 1e9
    extra = [c for c in frame.columns if c not in ("time", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")]
    fmt = lambda t: iso_utc(t, 3)  # noqa: E731
    return {
        "file": source,
        "kind": "ephemeris (GCRF)",
        "samples": int(len(frame)),
        "start": fmt(times.iloc[0]) if len(frame) else None,
        "end": fmt(times.iloc[-1]) if len(frame) else None,
        "step_s": float(np.median(steps)) if steps.size else None,
        "radius_km": [round(float(r.min()) / 1e3, 3), round(float(r.max()) / 1e3, 3)] if r.size else None,
        "above_equatorial_radius_km": ([round(float(r.min() - WGS84_A) / 1e3, 3), round(float(r.max() - WGS84_A) / 1e3, 3)]
                        if r.size else None),
        "speed_m_s": [round(float(v.min()), 3), round(float(v.max()), 3)] if v.size else None,
        "force_model": meta.get("force_model"),
        "extra_columns": extra,
    }


# --------------------------------------------------------------------------- other file kinds


def _state_summary(r_m, v_m_s, mu: float | None = None) -> dict:
    r = float(np.linalg.norm(r_m))
    el = classical_elements(np.asarray(r_m, float), np.asarray(v_m_s, float), mu or MU_EARTH)
    rounded = {k: (round(v, 6) if isinstance(v, float) else v) for k, v in el.items()}
    return {"radius_km": round(r / 1e3, 3), "above_equatorial_radius_km": round((r - WGS84_A) / 1e3, 3),
            "speed_m_s": round(float(np.linalg.norm(v_m_s)), 3), "elements": rounded}


def parameter_unit(name: str) -> str:
    """The unit of an estimated parameter from its name (``x`` m, ``vx`` m/s, ``range_bias:CPH`` m, ...)."""
    if name in ("x", "y", "z"):
        return "m"
    if name in ("vx", "vy", "vz"):
        return "m/s"
    family = name.split(":", 1)[0]
    unit = BIAS_UNITS.get(family) or FORCE_PARAMETERS.get(name) or CONSTRAINT_PARAMETERS.get(name)
    return unit if isinstance(unit, str) else ""


def state_info(data: bytes, source: str) -> dict:
    """A state file (JSON): epoch, frame, the state, its osculating elements, the estimated
    parameters with their sigmas, the force model and the solution's quality when recorded."""
    state = parse_state(data, source)
    doc = json.loads(data)
    out = {"file": source, "kind": "state (JSON)", "epoch": doc.get("epoch"), "frame": doc.get("frame"),
           "position_m": [float(x) for x in state.r_m], "velocity_m_s": [float(x) for x in state.v_m_s]}
    out.update(_state_summary(state.r_m, state.v_m_s, (state.constants or {}).get("mu_m3_s2")))
    sigma = state.sigma
    if sigma is None and state.covariance is not None:
        sigma = np.sqrt(np.clip(np.diag(state.covariance), 0.0, None))
    if sigma is not None:
        out["sigma"] = {p: float(s) for p, s in zip(state.parameters, sigma)}
        recorded = (doc.get("diagnostics") or {}).get("units")
        names = list(state.parameters)
        units = recorded if isinstance(recorded, list) and len(recorded) == len(names) else [
            parameter_unit(p) for p in names]
        out["units"] = dict(zip(names, units))
    out["covariance"] = state.covariance is not None
    out["force_model"] = doc.get("force_model")
    for key in ("quality", "earth_orientation"):
        if key in doc:
            out[key] = doc[key]
    converged = (doc.get("diagnostics") or {}).get("converged")
    if converged is not None:
        out["converged"] = converged
    return out


def tle_info(data: bytes, source: str) -> dict:
    """A TLE: name, catalogue number, epoch, the mean elements as written (TEME, SGP4 theory)."""
    tle = parse_tle(data.decode("ascii", errors="replace"), source)
    l2 = tle.line2
    return {"file": source, "kind": "TLE (SGP4 mean elements, TEME)", "name": tle.name, "catalogue_number": tle.satnum,
            "epoch": format_epoch(tle_epoch(tle)), "inclination_deg": float(l2[8:16]), "raan_deg": float(l2[17:25]),
            "eccentricity": float("0." + l2[26:33].strip()), "argp_deg": float(l2[34:42]),
            "mean_anomaly_deg": float(l2[43:51]), "mean_motion_rev_per_day": float(l2[52:63]),
            "bstar": bstar(tle.line1)}


def bstar(line1: str) -> float:
    """B* of a TLE line 1 (columns 54-61, an assumed leading decimal point and an exponent:
    ``-11606-4`` is -0.11606e-4 = -1.1606e-5 per Earth radius; Hoots & Roehrich, Spacetrack
    Report No. 3, 1980, the element set format)."""
    field = line1[53:61].strip()
    mantissa, exponent = field[:-2].strip(), field[-2:]
    sign = -1.0 if mantissa.startswith("-") else 1.0
    return sign * float("0." + mantissa.lstrip("+-").strip()) * 10.0 ** int(exponent)


def opm_info(data: bytes, source: str) -> dict:
    """A CCSDS OPM (KVN): object, epoch, frame, the state, its elements and sigmas."""
    opm = parse_opm(data.decode("utf-8", errors="replace"), source)
    out = {"file": source, "kind": f"CCSDS OPM {opm['version']}", **opm["meta"],
           "epoch": str(opm["epoch"]) + "Z", "frame": opm["ref_frame"], "time_system": opm["time_system"],
           "position_m": [float(x) for x in opm["r_m"]], "velocity_m_s": [float(x) for x in opm["v_m_s"]]}
    out.update(_state_summary(opm["r_m"], opm["v_m_s"]))
    cov = opm["covariance"]
    out["covariance"] = cov is not None
    if cov is not None:
        names = ("x", "y", "z", "vx", "vy", "vz")
        out["sigma"] = {n: float(s) for n, s in zip(names, np.sqrt(np.clip(np.diag(cov), 0, None)))}
        out["units"] = {n: parameter_unit(n) for n in names}
    return out


def _kvn_values(text: str) -> tuple[dict, list[str]]:
    """Keyword values (first occurrence) and the data lines of a CCSDS KVN message."""
    values, data = {}, []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("COMMENT"):
            continue
        key, sep, value = stripped.partition("=")
        if sep:
            values.setdefault(key.strip(), value.strip())
        elif stripped[:1].isdigit():
            data.append(stripped)
    return values, data


def oem_info(data: bytes, source: str) -> dict:
    """A CCSDS OEM (KVN): object, frame, the span and the number of states (and covariances)."""
    text = data.decode("utf-8", errors="replace")
    values, lines = _kvn_values(text)
    states = [l for l in lines if len(l.split()) >= 7 and "T" in l.split()[0]]
    epochs = [l.split()[0] for l in states]
    return {"file": source, "kind": f"CCSDS OEM {values.get('CCSDS_OEM_VERS', '?')}",
            "object_name": values.get("OBJECT_NAME"), "object_id": values.get("OBJECT_ID"),
            "center": values.get("CENTER_NAME"), "frame": values.get("REF_FRAME"),
            "time_system": values.get("TIME_SYSTEM"), "states": len(states),
            "start": epochs[0] if epochs else None, "end": epochs[-1] if epochs else None,
            "covariance_blocks": text.count("COVARIANCE_START")}


def tdm_info(data: bytes, source: str) -> dict:
    """A CCSDS TDM (KVN): participants, path, the samples per kind and station, the span."""
    raw = read_tdm(data, source)
    frame = raw.frame
    values, _ = _kvn_values(data.decode("utf-8", errors="replace"))
    per_station = {str(s): {str(k): int(n) for k, n in g["kind"].value_counts().sort_index().items()}
                   for s, g in frame.groupby("station")}
    times = iso_times(frame["time"]) if len(frame) else []
    return {"file": source, "kind": f"CCSDS TDM {values.get('CCSDS_TDM_VERS', '?')}",
            "time_system": values.get("TIME_SYSTEM"), "samples": int(len(frame)),
            "start": str(min(times)) if len(times) else None, "end": str(max(times)) if len(times) else None,
            "samples_per_station": per_station, "doppler_mode": raw.meta.get("doppler_mode"),
            "carrier_hz": raw.meta.get("carrier_hz")}


def _scalar(value, digits: int = 7) -> str:
    if value is None:
        return "-"
    if isinstance(value, (float, np.floating)) and not isinstance(value, bool):
        return format_number(float(value), digits)
    return str(value)


def _inline(value) -> str:
    """A list or small mapping on one line."""
    if isinstance(value, dict):
        if "message" in value:
            return f"{value.get('code', '')} {value.get('severity', '')}: {value['message']}".strip()
        return ", ".join(f"{k} {_inline(v)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return ", ".join(_inline(v) for v in value)
    return _scalar(value)


def _lines(key: str, value, indent: int, units: dict | None = None) -> list[str]:
    pad = " " * indent
    width = max(28 - indent, len(key) + 2)
    if isinstance(value, dict) and set(value) >= {"verdict", "reasons"}:      # a quality verdict
        out = [f"{pad}{key:<{width}}{value['verdict']}"]
        return out + [f"{pad}  {_inline(r)}" for r in value.get("reasons") or []]
    if isinstance(value, dict) and value:
        out = [f"{pad}{key}"]
        for k, v in value.items():
            if units is not None and not isinstance(v, (dict, list)):
                unit = units.get(k, "")
                out.append(f"{pad}  {k:<{max(width - 2, len(str(k)) + 2)}}{_scalar(v, 4)} {unit}".rstrip())
            else:
                out.extend(_lines(str(k), v, indent + 2))
        return out
    if isinstance(value, (list, tuple)) and any(isinstance(v, dict) for v in value):
        return [f"{pad}{key}"] + [f"{pad}  {_inline(v)}" for v in value]
    if isinstance(value, (list, tuple)):
        return [f"{pad}{key:<{width}}{_inline(value) if value else '-'}"]
    return [f"{pad}{key:<{width}}{_scalar(value)}"]


def format_mapping(summary: dict) -> str:
    """The summary for people, one ``key  value`` a line: nested mappings indented, floats to
    significant digits, sigmas with their units (``units``), a quality verdict with its reasons."""
    units = summary.get("units") if isinstance(summary.get("units"), dict) else None
    out = []
    for key, value in summary.items():
        if key == "units" and units is not None and "sigma" in summary:
            continue
        out.extend(_lines(key, value, 0, units if key == "sigma" else None))
    return "\n".join(out) + "\n"
