"""A ground station (:class:`Station`): WGS-84 geodetic position, an optional range-bias prior and
an optional 1-sigma uncertainty of its time tags.
Read by :mod:`trackproc.io.stations` and from a pass file's metadata."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Optional

from trackproc.errors import InputError
from trackproc.types.checks import check_name, check_station


@dataclass(frozen=True)
class Station:
    """A ground station: WGS-84 geodetic latitude/longitude (deg), height (m), range bias prior (m),
    1-sigma uncertainty of its time tags (s; ``refine``'s consider parameter, ``estimate
    --station-time-bias``'s a-priori sigma)."""

    name: str
    lat_deg: float
    lon_deg: float
    height_m: float
    range_bias_m: Optional[float] = None
    time_sigma_s: Optional[float] = None

    def as_dict(self) -> dict:
        """``{lat_deg, lon_deg, height_m[, range_bias_m][, time_sigma_s]}`` as stored in pass-file metadata."""
        out = {k: v for k, v in asdict(self).items() if k != "name"}
        for key in ("range_bias_m", "time_sigma_s"):
            if out[key] is None:
                del out[key]
        return out

    @classmethod
    def from_dict(cls, name: str, values: dict) -> "Station":
        """Inverse of :meth:`as_dict` (as read back from pass-file metadata)."""
        return cls(name, float(values["lat_deg"]), float(values["lon_deg"]), float(values["height_m"]),
                   None if values.get("range_bias_m") is None else float(values["range_bias_m"]),
                   None if values.get("time_sigma_s") is None else float(values["time_sigma_s"]))

    @classmethod
    def from_meta(cls, name, values, source: str) -> "Station":
        """A station as recorded in a file's metadata, checked (types, names, plausibility)."""
        check_name(name, "station name", file=source, column="stations")
        if not isinstance(values, dict):
            raise InputError("invalid station in the metadata", file=source, column=f"stations.{name}",
                             found=values, expected="an object with lat_deg, lon_deg, height_m")
        for key in ("lat_deg", "lon_deg", "height_m"):
            value = values.get(key)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError("invalid station in the metadata", file=source, column=f"stations.{name}.{key}",
                                 found=value, expected="a number")
        check_station(name, values["lat_deg"], values["lon_deg"], values["height_m"], file=source,
                      prefix=f"stations.{name}.")
        bias = values.get("range_bias_m")
        if bias is not None and (isinstance(bias, bool) or not isinstance(bias, (int, float))
                                 or not math.isfinite(bias)):
            raise InputError("invalid station in the metadata", file=source,
                             column=f"stations.{name}.range_bias_m", found=bias, expected="a finite number or null")
        tsig = values.get("time_sigma_s")
        if tsig is not None and (isinstance(tsig, bool) or not isinstance(tsig, (int, float))
                                 or not (math.isfinite(tsig) and tsig >= 0)):
            raise InputError("invalid station in the metadata", file=source,
                             column=f"stations.{name}.time_sigma_s", found=tsig,
                             expected="a finite number of seconds >= 0, or null")
        return cls.from_dict(name, values)
