"""Summary of a pass file (``trackproc info``): stations, passes, kinds, carrier and mode.

:func:`summarize` returns a :class:`PassFileInfo`; :func:`info_dict` gives its JSON form and
:func:`format_info` a plain aligned text table for people. Times are UTC ISO 8601 with ``Z``,
durations in seconds, elevations in degrees.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from trackproc.io.passfile import COLUMNS, KINDS, PassTable, iso_times


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
    import numpy as np

    from trackproc.constants import WGS84_A

    times = frame["time"]
    r = np.linalg.norm(frame[["x_m", "y_m", "z_m"]].to_numpy(float), axis=1)
    v = np.linalg.norm(frame[["vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy(float), axis=1)
    steps = np.diff(times.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy().astype(np.int64)) / 1e9
    extra = [c for c in frame.columns if c not in ("time", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")]
    from trackproc.isotime import iso_utc

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
