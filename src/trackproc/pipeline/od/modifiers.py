"""The measurement modifiers an estimation problem's options ask for (steps 3-5 of
:mod:`trackproc.pipeline.od.problem`): per-station range biases, per-pass or per-station Doppler
offsets and drifts with the oscillator's wander, angle biases and station time-tag offsets, each a
:class:`~trackproc.models.modifiers.Modifier` that owns its drivers (:func:`bias_modifiers`)."""

from __future__ import annotations

import numpy as np

from trackproc.errors import InputError
from trackproc.models import modifiers as md
from trackproc.pipeline.od.options import EstimateOptions, apriori_for


def wanted_stations(option, available: list, column: str, family: str, what: str, none: str = "") -> list:
    """The stations a per-station bias option asks for: ``True`` all of ``available``, a list those
    (each once, each one of ``available``: else :class:`InputError` naming ``column``), else none."""
    if option is True:
        return list(available)
    if not option:
        return []
    wanted = list(option)
    dup = sorted({s for s in wanted if wanted.count(s) > 1})
    if dup:
        raise InputError("duplicate parameter", column=column, found=f"{family}:{dup[0]}", expected="each station once")
    for s in wanted:
        if s not in available:
            raise InputError(what, column=column, found=s, expected="one of " + (", ".join(available) or none))
    return wanted


def range_bias_modifiers(opt: EstimateOptions, kinds_by_station: dict, known: dict, apriori) -> list:
    """A :class:`~trackproc.models.modifiers.RangeBias` per station with ranges: estimated for the
    stations ``--range-bias`` asks for, held at the stations table's known bias for the others."""
    range_stations = sorted(s for s, k in kinds_by_station.items() if "range" in k)
    wanted = wanted_stations(opt.range_bias, range_stations, "--range-bias", "range_bias",
                             "range bias for a station without ranges", "(no station has ranges)")
    out = []
    for s in range_stations:
        prior_value = getattr(known[s], "range_bias_m", None)
        if s in wanted:
            out.append(md.RangeBias(s, prior_value or 0.0,
                                    apriori_sigma=apriori_for(f"range_bias:{s}", "range_bias", apriori)))
        elif prior_value:
            out.append(md.RangeBias(s, prior_value, selected=False))     # a known bias from the stations table
    return out


def frequency_modifiers(opt: EstimateOptions, frame, t_s, apriori) -> list:
    """``--doppler-bias``: a :class:`~trackproc.models.modifiers.DopplerOffset` (and
    :class:`~trackproc.models.modifiers.DopplerDrift` from the first sample) per pass or station
    with Doppler or range-rate samples, each with the :class:`~trackproc.models.modifiers.OscillatorWander`
    of that transmitter (given by ``--oscillator-noise`` or estimated). ``auto``: offset and drift
    for the passes (stations) of one-way Doppler only — a transmitter of its own, whose offset is
    kHz at VHF and whose drift DopTrack's passes all show (0.3-0.7 Hz/s); a drift a pass does not
    need costs that pass a little precision and no bias."""
    bias = "none" if opt.doppler_bias is None else opt.doppler_bias
    if bias == "none":
        return []
    if bias == "auto":
        rr_rows = (frame["kind"] == "doppler") & (frame["_mode"] == "one-way")
        if not rr_rows.any():
            return []
        bias = "offset+drift"
    else:
        rr_rows = np.isin(frame["kind"], ["doppler", "range_rate"])
    keys_col = "pass_id" if opt.doppler_bias_per == "pass" else "station"
    keys = frame[keys_col][rr_rows]
    first = {key: float(t_s[rr_rows][keys == key].min()) for key in np.unique(keys)}
    if not len(first):
        raise InputError("no Doppler or range-rate samples for --doppler-bias", column="--doppler-bias",
                         found=opt.doppler_bias, expected="pass files with doppler or range_rate samples")
    out = []
    for key in sorted(first):
        out.append(md.DopplerOffset(key, apriori_sigma=apriori_for(f"doppler_offset:{key}", "doppler_offset",
                                                                   apriori)))
        if bias == "offset+drift":
            out.append(md.DopplerDrift(key, float(first[key]),
                                       apriori_sigma=apriori_for(f"doppler_drift:{key}", "doppler_drift", apriori)))
        out.append(md.OscillatorWander(key, opt.oscillator_noise))
    return out


def angle_modifiers(opt: EstimateOptions, kinds_by_station: dict, apriori) -> list:
    """``--angle-bias``: azimuth and elevation biases per station with angles."""
    out = []
    if opt.angle_bias:
        for s, k in sorted(kinds_by_station.items()):
            if "azimuth" in k:
                out.append(md.AzimuthBias(s, apriori_sigma=apriori_for(f"az_bias:{s}", "az_bias", apriori)))
            if "elevation" in k:
                out.append(md.ElevationBias(s, apriori_sigma=apriori_for(f"el_bias:{s}", "el_bias", apriori)))
    return out


def time_bias_modifiers(opt: EstimateOptions, stations_here, known: dict, apriori) -> list:
    """``--station-time-bias``: a :class:`~trackproc.models.modifiers.StationTimeBias` per station
    asked for; a-priori sigma from ``--apriori-sigma``, else the station's ``time_sigma_s`` (none
    given: no a-priori); a station with ``time_sigma_s`` 0 (exact tags) gets none."""
    wanted = wanted_stations(opt.station_time_bias, sorted(stations_here), "--station-time-bias-station",
                             "time_bias", "time bias for a station without samples")
    out = []
    for s in wanted:
        sigma = apriori_for(f"time_bias:{s}", "time_bias", apriori)
        stated = getattr(known.get(s), "time_sigma_s", None)
        if sigma is None and stated is not None:
            if stated == 0.0:
                continue                                          # exact time tags
            sigma = stated
        out.append(md.StationTimeBias(s, apriori_sigma=sigma))
    # tags of every station late by the same amount are the orbit moved along its track and turned
    # with the Earth (an axisymmetric field cannot tell): one offset must be fixed or constrained
    free = {m.key for m in out if m.driver.apriori_sigma is None}
    if free and free == set(stations_here):
        raise InputError("a time offset common to every station cannot be estimated (it is the orbit moved along "
                         "its track)", column="--station-time-bias", found=", ".join(sorted(free)),
                         expected="--station-time-bias-station for the stations in doubt, or an a-priori sigma "
                                  "(the stations table's time_sigma_s, or --apriori-sigma time_bias=S)")
    return out


def bias_modifiers(opt: EstimateOptions, frame, t_s, known, apriori) -> list:
    """Every modifier the options ask for, in the order of their drivers in the extended state."""
    # sets of the Python strings, not np.unique: sorting 24,000 str objects cost ~10 ms
    kinds_by_station = {s: set(frame["kind"][frame["station"] == s].tolist())
                        for s in sorted(set(frame["station"].tolist()))}
    return (range_bias_modifiers(opt, kinds_by_station, known, apriori) + frequency_modifiers(opt, frame, t_s, apriori)
            + angle_modifiers(opt, kinds_by_station, apriori)
            + time_bias_modifiers(opt, kinds_by_station, known, apriori))
