"""Range corrections of an estimation problem: troposphere and the target's centre-of-mass offset.

For every ``range`` sample (any source: laser normal points, radar, a TDM), the modelled range
gets :class:`trackproc.models.troposphere.RangeCorrections` added: the Mendes–Pavlis optical
delay at the sample's elevation from the station's meteorological records (CRD ``20`` records
carried in the pass file's metadata, interpolated to the sample; the standard atmosphere where
there are none), and minus the centre-of-mass offset (``--com-offset``, LAGEOS 0.251 m).

``troposphere``: ``"auto"`` applies Mendes–Pavlis to ranges of laser sessions (a CRD wavelength
in the metadata) whose file does not say it is already applied, ``"mendes-pavlis"`` to every
range (the wavelength from the session, else ``wavelength_nm``, else an error: the model is
optical only), ``"none"`` to none.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from trackproc.errors import InputError

TROPOSPHERE_MODELS = ("auto", "mendes-pavlis", "none")


def _crd_meta(meta: dict) -> list[dict]:
    """The ``crd`` metadata blocks of a pass file (at the top, or per input after ingest)."""
    found = [meta["crd"]] if isinstance(meta.get("crd"), dict) else []
    for extra in (meta.get("inputs") or {}).values():
        if isinstance(extra, dict) and isinstance(extra.get("crd"), dict):
            found.append(extra["crd"])
    return found


def _utc_ns(values) -> np.ndarray:
    t = pd.to_datetime(pd.Series(values), utc=True)
    return t.dt.tz_localize(None).to_numpy("datetime64[ns]").astype(np.int64)


def build(frame: pd.DataFrame, tables, stations: dict, *, troposphere: str = "auto", com_offset_m: float = 0.0,
          wavelength_nm: float | None = None):
    """The :class:`~trackproc.models.troposphere.RangeCorrections` of the range rows of ``frame``
    (the merged samples, columns ``time``, ``station``, ``kind``, ``_source``), or None when
    nothing applies. ``tables``: ``(source, PassTable)``; ``stations``: name -> Station."""
    from trackproc.dynamics.geodesy import DEG
    from trackproc.io.crd import meteo_at
    from trackproc.models import troposphere as tp

    if troposphere not in TROPOSPHERE_MODELS:
        raise InputError("unknown troposphere model", column="--troposphere", found=troposphere,
                         expected=", ".join(TROPOSPHERE_MODELS))
    if not (isinstance(com_offset_m, (int, float)) and math.isfinite(com_offset_m)):
        raise InputError("invalid centre-of-mass offset", column="--com-offset", found=com_offset_m,
                         expected="a finite offset in metres")
    if wavelength_nm is not None and not (tp.WAVELENGTH_RANGE_UM[0] * 1e3 <= wavelength_nm
                                          <= tp.WAVELENGTH_RANGE_UM[1] * 1e3):
        raise InputError("wavelength outside the Mendes-Pavlis model", column="--wavelength-nm", found=wavelength_nm,
                         expected="355 to 1064 nm (an optical wavelength)")
    rows = np.flatnonzero(frame["kind"].astype(str).to_numpy() == "range")
    if rows.size == 0 or (troposphere == "none" and com_offset_m == 0.0):
        return None
    sub = frame.iloc[rows]
    t_ns = sub["time"].dt.tz_convert("UTC").dt.tz_localize(None).to_numpy("datetime64[ns]")
    station = sub["station"].astype(str).to_numpy()
    source = sub["_source"].to_numpy()
    n = rows.size
    pressure, temperature, humidity = (np.full(n, np.nan) for _ in range(3))
    wavelength = np.full(n, np.nan)
    applied = np.zeros(n, dtype=bool)
    for src, table in tables:
        mine = source == src
        if not mine.any():
            continue
        for crd in _crd_meta(table.meta or {}):
            for st in set(station[mine]):
                pick = mine & (station == st)
                p, t, h = meteo_at(crd.get("meteo") or {}, st, t_ns[pick])
                have = np.isfinite(p)
                for arr, val in ((pressure, p), (temperature, t), (humidity, h)):
                    arr[np.flatnonzero(pick)[have]] = val[have]
            for s in crd.get("sessions") or []:
                start, end = _utc_ns([s["start"], s["end"]])
                t64 = t_ns.astype(np.int64)
                pick = mine & (station == s["station"]) & (t64 >= start - 3600e9) & (t64 <= end + 3600e9)
                if s.get("wavelength_nm"):
                    wavelength[pick] = float(s["wavelength_nm"])
                applied[pick] |= bool(s.get("troposphere_applied"))
    use_tropo = np.zeros(n, dtype=bool)
    if troposphere == "auto":
        use_tropo = np.isfinite(wavelength) & ~applied
    elif troposphere == "mendes-pavlis":
        use_tropo = np.ones(n, dtype=bool)
        if wavelength_nm is not None:
            wavelength = np.where(np.isfinite(wavelength), wavelength, wavelength_nm)
        if not np.all(np.isfinite(wavelength)):
            i = int(np.flatnonzero(~np.isfinite(wavelength))[0])
            raise InputError("the Mendes-Pavlis troposphere needs the laser wavelength", file=str(source[i]),
                             column="--wavelength-nm", found=f"range samples of {station[i]} without one",
                             expected="--wavelength-nm NM (or a CRD input, whose C0 record gives it)")
        if applied.any():
            i = int(np.flatnonzero(applied)[0])
            raise InputError("tropospheric correction already applied to these ranges", file=str(source[i]),
                             column="--troposphere", found="mendes-pavlis",
                             expected="--troposphere auto or none for CRD sessions whose H4 says it is applied")
    lat = np.array([stations[s].lat_deg * DEG for s in station])
    height = np.array([stations[s].height_m for s in station])
    wavelength = np.where(np.isfinite(wavelength), wavelength, tp.DEFAULT_WAVELENGTH_UM * 1e3)
    return _Masked(tp.RangeCorrections(rows=rows, lat_rad=lat, height_m=height, pressure_hpa=pressure,
                                       temperature_k=temperature, humidity_percent=humidity,
                                       wavelength_um=wavelength * 1e-3, troposphere=bool(use_tropo.any()),
                                       com_offset_m=float(com_offset_m)), use_tropo)


class _Masked:
    """Range corrections with the troposphere applied on a subset of the rows only."""

    def __init__(self, corrections, tropo_mask: np.ndarray):
        self.corrections = corrections
        self.rows = corrections.rows
        self.tropo_mask = tropo_mask

    @property
    def applied_troposphere(self) -> int:
        return int(self.tropo_mask.sum())

    def values(self, elevation_rad) -> np.ndarray:
        full = self.corrections.values(elevation_rad)
        if self.tropo_mask.all():
            return full
        com = np.full(len(self.rows), -self.corrections.com_offset_m)
        return np.where(self.tropo_mask, full, com)

    def subset(self, mask):
        """The corrections of the samples kept by the boolean ``mask`` (renumbered), or None."""
        from dataclasses import replace

        mask = np.asarray(mask, bool)
        keep = mask[self.rows]
        if not keep.any():
            return None
        new_index = np.cumsum(mask) - 1
        c = self.corrections
        picked = {k: getattr(c, k)[keep] for k in ("lat_rad", "height_m", "pressure_hpa", "temperature_k",
                                                     "humidity_percent", "wavelength_um")}
        return _Masked(replace(c, rows=new_index[self.rows[keep]], **picked), self.tropo_mask[keep])

    def add_to(self, computed: np.ndarray, meas, geometry) -> None:
        """Add the corrections to ``computed`` (in place) at the elevations of the current orbit."""
        rows = self.rows
        d = geometry.state[rows, :3] - meas.r_st[rows]
        up = np.einsum("nj,nj->n", meas.gcrf_to_enu[rows, 2, :], d)
        elevation = np.arcsin(np.clip(up / np.linalg.norm(d, axis=-1), -1.0, 1.0))
        computed[rows] += self.values(elevation)
