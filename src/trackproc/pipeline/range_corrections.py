"""Range corrections of an estimation problem: troposphere and the target's centre-of-mass offset.

For every ``range`` sample (any source: laser normal points, radar, a TDM) the options add
driver-free modifiers (:mod:`trackproc.models.modifiers`): the Mendes–Pavlis optical delay
(:class:`trackproc.models.troposphere.TroposphereDelay`) at the sample's elevation from the
station's meteorological records (CRD ``20`` records carried in the pass file's metadata,
interpolated to the sample; the standard atmosphere where there are none), and
:class:`~trackproc.models.troposphere.CentreOfMassOffset` (``--com-offset``, LAGEOS 0.251 m).

``troposphere``: ``"auto"`` applies Mendes–Pavlis to the ranges of laser sessions (a CRD
wavelength in the metadata) whose file does not say it is already applied; ``"mendes-pavlis"``
to every range (the session's wavelength, else ``wavelength_nm``, else an error: the model is
optical only); ``"none"`` to none.
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.errors import InputError
from trackproc.models import troposphere as tp
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.geodesy import DEG
from trackproc.models.station_tides import SolidTideDisplacement

TROPOSPHERE_MODELS = ("auto", "mendes-pavlis", "none")
#: A session's samples are matched to it within this margin of its H4 span, s.
_SPAN_MARGIN_S = 3600.0


def _crd_meta(meta: dict) -> list[dict]:
    """The ``crd`` metadata blocks of a pass file (at the top, or per input after ingest)."""
    found = [meta["crd"]] if isinstance(meta.get("crd"), dict) else []
    for extra in (meta.get("inputs") or {}).values():
        if isinstance(extra, dict) and isinstance(extra.get("crd"), dict):
            found.append(extra["crd"])
    return found


def check(troposphere: str, com_offset_m: float, wavelength_nm) -> None:
    """The options' values (one-line errors)."""
    if troposphere not in TROPOSPHERE_MODELS:
        raise InputError("unknown troposphere model", column="--troposphere", found=troposphere,
                         expected=", ".join(TROPOSPHERE_MODELS))
    if isinstance(com_offset_m, bool) or not (isinstance(com_offset_m, (int, float)) and math.isfinite(com_offset_m)):
        raise InputError("invalid centre-of-mass offset", column="--com-offset", found=com_offset_m,
                         expected="a finite offset in metres")
    lo, hi = (x * 1e3 for x in tp.WAVELENGTH_RANGE_UM)
    if wavelength_nm is not None and not (lo <= wavelength_nm <= hi):
        raise InputError("wavelength outside the Mendes-Pavlis model", column="--wavelength-nm", found=wavelength_nm,
                         expected="355 to 1064 nm (an optical wavelength)")


def range_correction_modifiers(frame: dict, tables, stations: dict, epoch, *, troposphere: str = "auto",
                               com_offset_m: float = 0.0, wavelength_nm: float | None = None,
                               solid_tides: bool | None = None) -> list:
    """The correction modifiers of the range samples of ``frame`` (merged samples, numpy columns
    ``time``, ``kind``, ``station``, ``_source``); ``tables``: ``(source, PassTable)``; ``stations``: name -> Station;
    ``epoch``: the solution epoch (UTC datetime64) the samples' seconds count from;
    ``solid_tides``: the stations' solid-Earth tide displacement on every range (None: on when
    the ranges come from CRD files, whose SINEX coordinates are tide-free)."""
    check(troposphere, com_offset_m, wavelength_nm)
    is_range = frame["kind"] == "range"
    if not is_range.any():
        return []

    out = []
    if com_offset_m != 0.0:
        out.append(tp.CentreOfMassOffset(com_offset_m))
    ref = ts.datetime64_to_jd_utc(np.datetime64(epoch, "ns"))
    range_sources = set(frame["_source"][is_range].tolist())
    if solid_tides is None:
        solid_tides = any(_crd_meta(table.meta or {}) for source, table in tables if source in range_sources)
    if solid_tides:
        out.append(SolidTideDisplacement(tuple(float(a) for a in ref)))
    if troposphere == "none":
        return out

    def seconds(iso) -> np.ndarray:
        import pandas as pd  # start-up: pandas (~0.15 s) only for the times of CRD sessions and meteo

        t = pd.to_datetime(pd.Series(list(iso), dtype=object), utc=True).dt.tz_localize(None)
        return np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(t.to_numpy("datetime64[ns]")), ref), float)

    range_stations = sorted(set(frame["station"][is_range]))
    meteo: dict = {}
    sessions: dict = {}                     # station -> [(start_s, end_s, wavelength_nm, applied)]
    for source, table in tables:
        if source not in range_sources:
            continue
        for crd in _crd_meta(table.meta or {}):
            for st, rec in (crd.get("meteo") or {}).items():
                if rec.get("time"):
                    m = meteo.setdefault(st, [[], [], [], []])
                    for k, key in enumerate(("pressure_hpa", "temperature_k", "humidity_percent")):
                        m[k + 1].extend(float(v) if v is not None else math.nan for v in rec[key])
                    m[0].extend(seconds(rec["time"]))
            for s in crd.get("sessions") or []:
                start, end = seconds([s["start"], s["end"]])
                sessions.setdefault(s["station"], []).append(
                    (start - _SPAN_MARGIN_S, end + _SPAN_MARGIN_S, s.get("wavelength_nm"),
                     bool(s.get("troposphere_applied"))))
    for st in range_stations:
        site = stations[st]
        lat, height = site.lat_deg * DEG, site.height_m
        m = meteo.get(st)
        kw = {} if m is None else {"meteo_t_s": m[0], "pressure_hpa": m[1], "temperature_k": m[2],
                                   "humidity_percent": m[3]}
        spans = _disjoint(sessions.get(st, []))
        for start, end, wl, applied in spans:
            if applied:
                if troposphere == "mendes-pavlis":
                    raise InputError("tropospheric correction already applied to these ranges", column="--troposphere",
                                     found=f"station {st}, a CRD session saying so (H4)",
                                     expected="--troposphere auto or none for such sessions")
                continue
            wl = wl or (wavelength_nm if troposphere == "mendes-pavlis" else None)
            if not wl and troposphere == "mendes-pavlis":
                raise InputError("the Mendes-Pavlis troposphere needs the laser wavelength", column="--wavelength-nm",
                                 found=f"a CRD session of {st} without a C0 wavelength",
                                 expected="--wavelength-nm NM")
            if wl:
                out.append(tp.TroposphereDelay(st, lat, height, wl * 1e-3, spans_s=[(start, end)], **kw))
        if troposphere == "mendes-pavlis":
            rest = tp.TroposphereDelay(st, lat, height, (wavelength_nm or tp.DEFAULT_WAVELENGTH_UM * 1e3) * 1e-3,
                                       exclude_s=[(a, b) for a, b, _, _ in spans], **kw)
            rows = np.flatnonzero(is_range & (frame["station"] == st))
            if wavelength_nm is None and rows.size and _outside(frame, rows, spans, seconds):
                raise InputError("the Mendes-Pavlis troposphere needs the laser wavelength", column="--wavelength-nm",
                                 found=f"range samples of {st} outside any CRD session",
                                 expected="--wavelength-nm NM (a CRD input gives it in its C0 record)")
            out.append(rest)
    return out


def _disjoint(spans: list) -> list:
    """Session spans (with their margins) made disjoint: overlapping spans of the same wavelength
    and flag merge, others split at the middle of the overlap (no sample is corrected twice)."""
    out: list = []
    for start, end, wl, applied in sorted(spans, key=lambda s: s[0]):
        if out and start <= out[-1][1]:
            a, b, wl0, ap0 = out[-1]
            if (wl0, ap0) == (wl, applied):
                out[-1] = (a, max(b, end), wl, applied)
                continue
            cut = 0.5 * (start + b)
            out[-1] = (a, cut, wl0, ap0)
            start = np.nextafter(cut, np.inf)
        out.append((start, end, wl, applied))
    return out


def _outside(frame, rows, spans, seconds) -> bool:
    """True when some of ``rows`` lie outside every span."""
    import pandas as pd  # start-up: as in range_correction_modifiers' seconds

    t = seconds(pd.Series(frame["time"][rows]).dt.strftime("%Y-%m-%dT%H:%M:%S.%fZ"))
    inside = np.zeros(t.shape, dtype=bool)
    for a, b, _, _ in spans:
        inside |= (t >= a) & (t <= b)
    return not inside.all()
