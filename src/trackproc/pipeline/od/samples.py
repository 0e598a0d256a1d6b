"""The samples of ``trackproc estimate``: pass tables merged and checked, stations resolved,
reception times in SI seconds from the solution epoch, stations in GCRF (steps 1-2 of
:mod:`trackproc.pipeline.estimate`)."""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import geodesy
from trackproc.dynamics import timescales as ts
from trackproc.errors import InputError
from trackproc.io.statefile import parse_epoch
from trackproc.io.validate import MAX_SPAN_S, stated_carrier
from trackproc.isotime import iso_utc_offset
from trackproc.models import observation as ob


#: The merged samples' columns: a pass file's, then each sample's file, carrier, link and row in its file.
SAMPLE_COLUMNS = ("time", "station", "pass_id", "kind", "value", "sigma", "_source", "_carrier", "_mode", "_row")


def groups(*columns) -> list:
    """``[(key, rows), ...]``: each distinct tuple of ``columns`` (equal-length arrays of text) in
    sorted order, as ``sorted(set(zip(*columns)))``, with the indices of its rows, increasing.
    By integer codes (each column's rank among its sorted distinct values) rather than a Python
    pass over the tuples and a string comparison per key: a day of samples has ~24,000 rows and
    ~40 passes."""
    if not columns or np.asarray(columns[0]).size == 0:
        return []
    code = np.zeros(np.asarray(columns[0]).size, np.int64)
    uniques = []
    for col in columns:
        values, ranks = _ranks(col)
        uniques.append(values)
        code = code * len(values) + ranks
    order = np.argsort(code, kind="stable")
    out = []
    for rows in np.split(order, np.flatnonzero(np.diff(code[order])) + 1):
        c, key = int(code[rows[0]]), []
        for values in reversed(uniques):
            c, r = divmod(c, len(values))
            key.append(values[r])
        out.append((tuple(reversed(key)), rows))
    return out


def _ranks(column) -> tuple[list, np.ndarray]:
    """The sorted distinct values of a text column (``str``) and each row's rank among them. A
    set and a dict of the few names (~1 ms for 24,000 rows) rather than numpy's conversion to
    fixed-width text and its sort (~2.6 ms); anything but strings goes that way."""
    items = np.asarray(column).tolist()
    try:
        values = sorted(set(items))
    except TypeError:
        values = None
    if values is None or not all(isinstance(v, str) for v in values):
        text, ranks = np.unique(np.asarray(column).astype(str), return_inverse=True)
        return [str(v) for v in text], ranks.reshape(-1)
    rank = {v: i for i, v in enumerate(values)}
    return [str(v) for v in values], np.fromiter(map(rank.__getitem__, items), np.int64, len(items))


def merge_tables(tables, kinds):
    """The samples of all files as one dict of numpy columns (:data:`SAMPLE_COLUMNS`; ``time``
    naive UTC datetime64[ns]) with their file, carrier and metadata checks."""
    parts, carriers, models, sources = [], [], [], []
    for source, table in tables:
        meta = table.meta or {}
        n = table.n_rows
        if n == 0:
            raise InputError("no samples", file=source, expected="a pass file with at least one sample")
        mode = meta.get("doppler_mode") or "one-way"
        kinds_here = set(table.column("kind").tolist())   # not np.unique: a sort of str objects
        if mode not in ob.MODES and kinds_here & set(ob.LINK_KINDS):
            raise InputError("unknown link mode", file=source, column="doppler_mode", found=mode,
                             expected="one-way or two-way (a round trip through a transponder of ratio 1)")
        carriers.append(stated_carrier(meta, file=source,
                                       needed="doppler" in kinds_here and (kinds is None or "doppler" in kinds)))
        models.append(meta.get("range_rate_model"))
        part = {name: table.column(name) for name in SAMPLE_COLUMNS[:6]}
        part["_source"] = np.full(n, source, dtype=object)
        part["_carrier"] = np.full(n, np.nan if carriers[-1] is None else carriers[-1], dtype=float)
        part["_mode"] = np.full(n, mode if mode in ob.MODES else "one-way", dtype=object)  # angles: any link
        part["_row"] = np.arange(n)
        parts.append(part)
        sources.append(source)
    frame = {name: np.concatenate([p[name] for p in parts]) for name in SAMPLE_COLUMNS}
    if kinds is not None:
        keep = np.isin(frame["kind"], list(kinds))
        frame = {name: values[keep] for name, values in frame.items()}
        if not keep.any():
            raise InputError("no samples of the requested kinds", column="--kinds", found=",".join(kinds),
                             expected="kinds present in the pass files")
    return frame, models


def check_samples(frame):
    value, sigma = np.asarray(frame["value"], float), np.asarray(frame["sigma"], float)
    bad = ~(np.isfinite(value))
    bad_sigma = ~(np.isfinite(sigma) & (sigma > 0))
    for mask, column, expected in ((bad, "value", "a finite number"), (bad_sigma, "sigma", "a positive number")):
        if mask.any():
            i = int(np.flatnonzero(mask)[0])
            raise InputError(f"invalid {column} at {iso_utc_offset(frame['time'][i])} ({frame['station'][i]}, "
                             f"{frame['kind'][i]}; sample {int(frame['_row'][i]) + 1} of the file)",
                             file=frame["_source"][i], column=column, found=frame[column][i], expected=expected)


def resolve_stations(frame, tables, stations):
    """Station objects for every station in the samples: --stations first, then metadata."""
    known = dict(stations or {})
    for source, table in tables:
        for name, st in table.stations().items():
            known.setdefault(name, st)
    missing = sorted(set(frame["station"].tolist()) - set(known))
    if missing:
        name = missing[0]
        src = frame["_source"][np.flatnonzero(frame["station"] == name)[0]]
        raise InputError("unknown station", file=src, column="station", found=name,
                         expected="a station of --stations or of the pass file's metadata"
                         + (f" ({', '.join(sorted(known))})" if known else " (give --stations STATIONS.csv)"))
    return known


def solution_epoch(option, initial, times):
    """The solution epoch (``--epoch``: ``initial``, ``first`` or a UTC time), at most
    :data:`~trackproc.io.validate.MAX_SPAN_S` (the propagation bound) from the samples' span: an
    epoch years away would only propagate to the step limit and fail."""
    if option is None or (isinstance(option, str) and option.lower() == "initial"):
        epoch = np.datetime64(initial.epoch, "ns")
        column = "--initial"
    elif isinstance(option, str) and option.lower() == "first":
        return np.datetime64(times.min(), "ns")
    else:
        epoch = parse_epoch(option, column="--epoch") if isinstance(option, str) else np.datetime64(option, "ns")
        column = "--epoch"
    lo, hi = np.datetime64(times.min(), "ns"), np.datetime64(times.max(), "ns")
    far = max(float((lo - epoch) / np.timedelta64(1, "s")), float((epoch - hi) / np.timedelta64(1, "s")), 0.0)
    if far > MAX_SPAN_S:
        raise InputError("the solution epoch is far from the samples", column=column,
                         found=f"{str(epoch.astype('datetime64[s]'))}Z, {far / 86400:.1f} days from the samples "
                               f"({str(lo.astype('datetime64[s]'))}Z to {str(hi.astype('datetime64[s]'))}Z)",
                         expected=f"an epoch within {MAX_SPAN_S / 86400:g} days of the samples (the propagation "
                                  "bound; --epoch first takes the first sample)")
    return epoch


def range_rate_model(option, file_models) -> str:
    """The range-rate model: the option, else the pass files' one (they must agree), else doppler."""
    model = option
    if model is None:
        found = sorted({m for m in file_models if m})
        if len(found) > 1:
            raise InputError("pass files disagree on the range-rate model", column="range_rate_model",
                             found=", ".join(found), expected="one model; choose with --range-rate-model")
        model = found[0] if found else "doppler"
    if model not in ob.RANGE_RATE_MODELS:
        raise InputError("unknown range-rate model", column="--range-rate-model", found=model,
                         expected=" or ".join(ob.RANGE_RATE_MODELS))
    return model


def utc_times(frame) -> np.ndarray:
    """The samples' UTC time tags as naive datetime64[ns]."""
    times = frame["time"]
    if getattr(times.dt, "tz", None) is not None:
        times = times.dt.tz_convert("UTC").dt.tz_localize(None)
    return times.to_numpy(dtype="datetime64[ns]")


def measurement_set(frame, t64, epoch, known, earth: str, eop, geometry: ob.MeasurementSet | None = None
                    ) -> ob.MeasurementSet:
    """The :class:`~trackproc.models.observation.MeasurementSet` of ``frame`` (:func:`merge_tables`): reception times
    in SI seconds from ``epoch`` (through TAI), every station in GCRF at its reception times
    (IAU 2006/2000A) with its velocity, acceleration and GCRF -> ENU rotation. ``geometry``: a set of
    the same samples and stations counted from another epoch, whose station geometry (a function of
    the reception times alone) is copied instead of transformed again."""
    epoch_jd = tuple(float(a) for a in ts.datetime64_to_jd_utc(epoch))
    jd1, jd2 = ts.datetime64_to_jd_utc(t64)
    t_s = np.asarray(ts.seconds_since((jd1, jd2), epoch_jd), float)
    n = len(frame["time"])
    if geometry is not None:
        return ob.MeasurementSet(t_s=t_s, kind=frame["kind"], station=frame["station"], pass_id=frame["pass_id"],
                                 observed=np.asarray(frame["value"], float), sigma=np.asarray(frame["sigma"], float),
                                 r_st=geometry.r_st.copy(), v_st=geometry.v_st.copy(),
                                 gcrf_to_enu=geometry.gcrf_to_enu.copy(), carrier_hz=frame["_carrier"],
                                 a_st=geometry.a_st.copy(), mode=frame["_mode"])
    r_st = np.empty((n, 3))
    v_st = np.empty((n, 3))
    a_st = np.empty((n, 3))
    enu = np.empty((n, 3, 3))
    station_col = frame["station"]
    for name in sorted(set(station_col)):
        rows = np.flatnonzero(station_col == name)
        st = known[name]
        lat, lon, r_itrf = geodesy.station_itrf(st, earth)
        track = geodesy.station_gcrf(r_itrf, jd1[rows], jd2[rows], eop)
        r_st[rows], v_st[rows], a_st[rows] = track.r, track.v, track.a
        enu[rows] = geodesy.enu_matrix(lat, lon) @ track.gcrf_to_itrf
    return ob.MeasurementSet(t_s=t_s, kind=frame["kind"], station=station_col, pass_id=frame["pass_id"],
                             observed=np.asarray(frame["value"], float), sigma=np.asarray(frame["sigma"], float),
                             r_st=r_st, v_st=v_st, gcrf_to_enu=enu, carrier_hz=frame["_carrier"], a_st=a_st,
                             mode=frame["_mode"])
