"""TDM segments to the canonical table (:class:`Converter`): each data keyword turned into a
measurement in SI units at a UTC reception time (RANGE, DOPPLER_*, RECEIVE_FREQ_n against its
nominal carrier, ANGLE_1/2), one link mode and one carrier per file.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from trackproc.constants import C_LIGHT
from trackproc.dynamics import timescales
from trackproc.errors import InputError
from trackproc.io.raw import RawMeasurements
from trackproc.io.tdm.keywords import DATA_KEYS, HEADER_KEYS, META_KEYS, RECEIVE_FREQ_KEYS
from trackproc.io.tdm.kvn import NS, Obs, Segment
from trackproc.io.tdm.metadata import SegmentConfig, segment_config

#: Largest accepted |received - nominal| / nominal: 1e-3 is 300 km/s one-way, far above any
#: Earth-orbit or interplanetary Doppler, far below any turnaround ratio (240/221 is 8.6 %).
MAX_RELATIVE_DOPPLER = 1e-3

class Converter:
    def __init__(self, source, header, segments, skipped, carrier_hz, halve_two_way):
        self.source = source
        self.header = header
        self.segments = segments
        self.skipped = skipped
        self.carrier_hz = carrier_hz
        self.halve_two_way = halve_two_way
        self.rows: list[tuple] = []            # (time_ns, station, kind, value, row)
        self.columns: dict[str, list] = {}
        self.warnings: list[str] = []
        self.doppler_mode: tuple | None = None  # (mode, segment number)
        self.nominals: list[tuple] = []          # (nominal_hz, row)
        self.range_modes: set = set()
        self.time_systems: list = []
        self.segment_info: list = []

    def error(self, message, row=None, column=None, found=None, expected=None):
        return InputError(message, file=self.source, row=row, column=column, found=found,
                          expected=expected)

    def run(self) -> RawMeasurements:
        for seg in self.segments:
            cfg, info = segment_config(seg, self.source, self.warnings)
            self.time_systems.append(cfg.time_system)
            self.segment_info.append(info)
            self._convert(seg, cfg)

        if not self.rows:
            what = (", ".join(f"{k} x{n}" for k, n in sorted(self.skipped.items()))
                    or "no data lines")
            raise self.error("no supported measurements (RANGE, DOPPLER_INSTANTANEOUS, "
                             "DOPPLER_INTEGRATED, RECEIVE_FREQ_n, ANGLE_1/ANGLE_2) in the file",
                             found=what)

        self.rows.sort(key=lambda r: r[4])
        time = np.array([r[0] for r in self.rows], dtype="int64").astype("datetime64[ns]")
        frame = pd.DataFrame({
            "time": pd.Series(time).dt.tz_localize("UTC"),
            "station": [r[1] for r in self.rows],
            "kind": [r[2] for r in self.rows],
            "value": np.array([r[3] for r in self.rows], dtype="float64"),
            "sigma": np.full(len(self.rows), np.nan),
            "row": np.array([r[4] for r in self.rows], dtype="int64"),
            # the unit the file wrote (ANGLE_1/2 in degrees), so that messages quote its values
            "unit": ["deg" if r[2] in ("azimuth", "elevation") else "" for r in self.rows],
        })

        self.warnings.extend(f"non-standard TDM keyword {key} skipped ({n} lines)"
                             for key, n in sorted(self.skipped.items())
                             if key not in DATA_KEYS | META_KEYS | HEADER_KEYS)
        meta = {
            "source": self.source,
            "format": "CCSDS TDM (KVN)",
            "tdm_version": self.header["CCSDS_TDM_VERS"][0],
            "tdm_segments": len(self.segments),
            "time_scale": "UTC",
            "source_time_systems": sorted(set(self.time_systems)),
            "skipped_keywords": dict(sorted(self.skipped.items())),
            "warnings": self.warnings,
            "tdm_segment_info": self.segment_info,
        }
        if "ORIGINATOR" in self.header:
            meta["originator"] = self.header["ORIGINATOR"][0]
        if self.doppler_mode is not None:
            meta["doppler_mode"] = self.doppler_mode[0]
        carrier = self._file_carrier()
        if carrier is not None:
            meta["carrier_hz"] = carrier
        if self.range_modes:
            meta["range_two_way_halved"] = self.halve_two_way and "two-way" in self.range_modes
            meta["range_source_paths"] = sorted(self.range_modes)
            # the file's link mode (``doppler_mode``) is what estimate models ranges with too
            if self.doppler_mode is None and len(self.range_modes) == 1:
                meta["doppler_mode"] = next(iter(self.range_modes))
            elif self.range_modes - {meta.get("doppler_mode")}:
                link = meta.get("doppler_mode") or "one-way (the default)"
                self.warnings.append(
                    f"RANGE paths are {' and '.join(sorted(self.range_modes))} but the file's link mode is {link}, "
                    "which estimate applies to every range, range-rate and Doppler sample: split the file by path")
            if "two-way" in self.range_modes:
                self.warnings.append(
                    "two-way RANGE values " + ("halved (written as round trips)" if self.halve_two_way
                                               else "taken as one-way equivalents (as the spec's examples "
                                               "write them); use --tdm-two-way-range round-trip if "
                                               "this file holds full round trips"))
        column = {kind: ", ".join(keys) for kind, keys in self.columns.items()}
        return RawMeasurements(frame=frame, source=self.source, column=column, meta=meta)

    # -- data -------------------------------------------------------------------------------

    def _convert(self, seg: Segment, cfg: SegmentConfig):
        if not seg.obs:
            return
        naive = np.array([o.naive_ns for o in seg.obs], dtype="int64")
        utc = timescales.scale_ns_to_utc_ns(naive, cfg.time_system)
        if utc is None:
            raise self.error("epoch outside the UTC leap-second table (before 1960)",
                             row=seg.obs[0].row, column=seg.obs[0].key)
        shift = self._integration_shift_ns(seg, cfg)
        corr = cfg.corrections

        # TRANSMIT_FREQ_n / TRANSMIT_FREQ_RATE_n only serve as the nominal of RECEIVE_FREQ,
        # and only for n = the transmitter (first entry of PATH); others are counted as skipped.
        tx_index = cfg.path[0] if cfg.path else None
        has_receive = any(o.key in RECEIVE_FREQ_KEYS for o in seg.obs)
        tx_freq, tx_rate, other_tx = [], [], set()
        for o, t in zip(seg.obs, utc):
            if not o.key.startswith("TRANSMIT_FREQ"):
                continue
            if not has_receive or int(o.key[-1]) != tx_index:
                self.skipped[o.key] = self.skipped.get(o.key, 0) + 1
                if not o.key.startswith("TRANSMIT_FREQ_RATE_"):
                    other_tx.add(o.key)
            elif o.key.startswith("TRANSMIT_FREQ_RATE_"):
                tx_rate.append((int(t), o.value))
            else:
                tx_freq.append((int(t), o.value + corr.get("CORRECTION_TRANSMIT", 0.0)))
        receive = []   # (time_ns, received_hz, obs)

        for o, t in zip(seg.obs, utc):
            t = int(t)
            key = o.key
            if key.startswith("TRANSMIT_FREQ"):
                continue
            self._check_path(o, cfg, need_link=key != "ANGLE_1" and key != "ANGLE_2")
            if key == "RANGE":
                raw = o.value + corr.get("CORRECTION_RANGE", 0.0)
                if cfg.range_units == "RU":
                    raise self.error(
                        "RANGE in range units (RU) is not supported: RU are defined by a "
                        "mission ICD (the DSN's depend on the uplink band and frequency) and "
                        "are ambiguous modulo RANGE_MODULUS; convert to km or s",
                        row=o.row, column=key, found="RANGE_UNITS = RU",
                        expected="RANGE_UNITS = km or s")
                metres = raw * 1000.0 if cfg.range_units == "km" else raw * C_LIGHT
                if cfg.mode == "two-way" and self.halve_two_way:
                    metres /= 2.0
                self.range_modes.add(cfg.mode)
                self._emit(t, cfg.station, "range", metres, o.row, key)
            elif key in ("DOPPLER_INSTANTANEOUS", "DOPPLER_INTEGRATED"):
                self._set_doppler_mode(cfg, o)
                kms = o.value + corr.get("CORRECTION_DOPPLER", 0.0)
                tt = t + shift if key == "DOPPLER_INTEGRATED" else t
                self._emit(tt, cfg.station, "range_rate", kms * 1000.0, o.row, key)
            elif key in RECEIVE_FREQ_KEYS:
                self._set_doppler_mode(cfg, o)
                received = cfg.freq_offset + o.value + corr.get("CORRECTION_RECEIVE", 0.0)
                receive.append((t + shift, received, o))
            elif key in ("ANGLE_1", "ANGLE_2"):
                if cfg.angle_type != "AZEL":
                    raise self.error(
                        "only ANGLE_TYPE = AZEL (azimuth, elevation) is supported",
                        row=o.row, column=key, found=f"ANGLE_TYPE = {cfg.angle_type}"
                        if cfg.angle_type else "no ANGLE_TYPE in the META block",
                        expected="ANGLE_TYPE = AZEL")
                deg = o.value + corr.get(f"CORRECTION_{key}", 0.0)
                if key == "ANGLE_1":
                    self._emit(t, cfg.station, "azimuth", math.radians(deg % 360.0), o.row, key)
                else:
                    self._emit(t, cfg.station, "elevation", math.radians(deg), o.row, key)

        if receive:
            self._receive_freq(receive, cfg, tx_freq, tx_rate, tx_index, other_tx)

    def _check_path(self, o: Obs, cfg: SegmentConfig, need_link: bool):
        if cfg.path_problem:
            raise self.error(f"cannot read {o.key} from a segment with {cfg.path_problem}",
                             row=o.row, column=o.key,
                             expected="PATH i,j (one-way) or i,j,i (two-way)")
        if need_link and cfg.mode is None:
            raise self.error(f"{o.key} needs PATH in its META block to tell one-way from "
                             "two-way", row=o.row, column=o.key,
                             expected="PATH = 2,1 (one-way) or 1,2,1 (two-way)")

    def _integration_shift_ns(self, seg: Segment, cfg: SegmentConfig) -> int:
        counted = [o for o in seg.obs
                   if o.key == "DOPPLER_INTEGRATED" or o.key in RECEIVE_FREQ_KEYS]
        if not counted:
            return 0
        interval, ref = cfg.integration_interval, cfg.integration_ref
        if interval is None or ref is None:
            if any(o.key == "DOPPLER_INTEGRATED" for o in counted):
                self.warnings.append(
                    f"segment {seg.number}: DOPPLER_INTEGRATED without INTEGRATION_INTERVAL "
                    "and INTEGRATION_REF; time tags taken as mid-interval")
            return 0
        half = round(interval * NS / 2)
        return {"START": half, "MIDDLE": 0, "END": -half}[ref]

    def _set_doppler_mode(self, cfg: SegmentConfig, o: Obs):
        if self.doppler_mode is None:
            self.doppler_mode = (cfg.mode, cfg.number)
        elif self.doppler_mode[0] != cfg.mode:
            raise self.error(
                f"segment {cfg.number} is {cfg.mode} but segment {self.doppler_mode[1]} is "
                f"{self.doppler_mode[0]}: one file must hold one Doppler mode (split it)",
                row=o.row, column=o.key, found=cfg.mode, expected=self.doppler_mode[0])

    def _receive_freq(self, receive, cfg: SegmentConfig, tx_freq, tx_rate, tx_index, other_tx):
        times = np.array([r[0] for r in receive], dtype="int64")
        if tx_freq:
            nominal = ramped_frequency(times, tx_freq, tx_rate)
            if cfg.mode == "two-way" and cfg.turnaround is not None:
                nominal = nominal * cfg.turnaround
            origin = f"TRANSMIT_FREQ_{tx_index}"
            if cfg.mode == "two-way" and cfg.turnaround is not None:
                origin += " x TURNAROUND_NUMERATOR/TURNAROUND_DENOMINATOR"
        elif self.carrier_hz is not None:
            nominal = np.full(len(times), float(self.carrier_hz))
            origin = "the carrier frequency given (--carrier-hz)"
        else:
            first = receive[0][2]
            extra = (f" ({', '.join(sorted(other_tx))} belong to a participant that does not "
                     f"transmit on PATH)" if other_tx else "")
            raise self.error(
                f"{first.key} needs the nominal carrier: segment {cfg.number} has no "
                f"TRANSMIT_FREQ_{tx_index}{extra}; pass --carrier-hz", row=first.row,
                column=first.key, expected=f"TRANSMIT_FREQ_{tx_index} data or --carrier-hz")
        for (t, received, o), f0 in zip(receive, nominal):
            shift = received - f0
            if not abs(shift) <= MAX_RELATIVE_DOPPLER * f0:
                raise self.error(
                    f"received frequency is {shift:+.6g} Hz from the nominal carrier "
                    f"{f0:.12g} Hz taken from {origin}: wrong carrier, missing FREQ_OFFSET or "
                    "turnaround ratio?", row=o.row, column=o.key, found=received,
                    expected=f"within {MAX_RELATIVE_DOPPLER:.1%} of {f0:.12g} Hz")
            self.nominals.append((float(f0), o.row))
            self._emit(t, cfg.station, "doppler", shift, o.row, o.key)

    def _file_carrier(self):
        if not self.nominals:
            return self.carrier_hz
        values = sorted(f for f, _ in self.nominals)
        median = values[len(values) // 2]
        for f, row in self.nominals:
            if abs(f - median) > MAX_RELATIVE_DOPPLER * median:
                raise self.error(
                    "the file mixes carriers of different nominal frequency; the canonical "
                    "table carries one (split the file)", row=row, found=f,
                    expected=f"about {median:.12g} Hz")
        return median

    def _emit(self, t, station, kind, value, row, key):
        self.rows.append((t, station, kind, value, row))
        keys = self.columns.setdefault(kind, [])
        if key not in keys:
            keys.append(key)


def ramped_frequency(times, tx_freq, tx_rate):
    """Transmit frequency at ``times`` (ns): the latest TRANSMIT_FREQ sample at or before each
    time (the first one for earlier times) plus the integral of the TRANSMIT_FREQ_RATE ramp,
    which is piecewise constant from each rate time tag to the next (503.0-B-2:
    "starting at the timetag and continuing until the next TRANSMIT_FREQ_RATE_n timetag")."""
    tx_freq = sorted(tx_freq)
    ft = np.array([t for t, _ in tx_freq], dtype="int64")
    fv = np.array([v for _, v in tx_freq], dtype="float64")
    k = np.clip(np.searchsorted(ft, times, side="right") - 1, 0, len(ft) - 1)
    if not tx_rate:
        return fv[k]
    tx_rate = sorted(tx_rate)
    bt = np.array([t for t, _ in tx_rate], dtype="int64")
    br = np.array([r for _, r in tx_rate], dtype="float64")
    cum = np.concatenate([[0.0], np.cumsum(br[:-1] * np.diff(bt) / NS)])

    def ramp(t):  # integral of the rate from the first rate tag to t, Hz
        j = np.searchsorted(bt, t, side="right") - 1
        inside = j >= 0
        jj = np.clip(j, 0, None)
        return np.where(inside, cum[jj] + br[jj] * (t - bt[jj]) / NS, 0.0)

    anchor = np.minimum(times, ft[k])  # = ft[k]; = t (no ramp) before the first sample
    return fv[k] + ramp(times) - ramp(anchor)
