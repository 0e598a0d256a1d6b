"""Orekit's orbit-determination configuration (``*.in``: the ``key = value`` files of Orekit's
``OrbitDetermination`` tutorial and tests) read into what trackproc takes: a stations table, an
initial state file and the sigma and bias options.

Syntax, as Orekit's ``KeyValueFileParser`` reads it: one ``key = value`` a line, ``#`` starts a
comment, indexed keys ``key [i] = value`` (one entry per ground station or acceleration). Units as
Orekit's tutorial takes them: the orbit in metres and m/s in ``inertial.frame`` at ``orbit.date``
(UTC), station latitude and longitude in degrees and altitude in metres (geodetic on the body
shape of ``body.equatorial.radius``/``body.inverse.flattening``, WGS-84 in every shipped file),
range sigma and biases in metres, angle sigma in degrees, ``mass`` in kg (1000 kg when absent,
Orekit's default), areas in m².

What has no counterpart in trackproc is not carried silently: :func:`read_orekit_config` lists
each such key the file switches on (``unused``) so the caller can say so.
"""

from __future__ import annotations

import math
import re

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.io.validate import check_name, check_station

#: Orekit's ``OrbitDetermination`` mass when the file gives none, kg.
DEFAULT_MASS_KG = 1000.0
_INDEXED = re.compile(r"^([A-Za-z0-9_.]+)\s*\[\s*(\d+)\s*\]$")
_FRAMES = {"EME2000": "EME2000", "J2000": "EME2000", "GCRF": "GCRF", "TEME": "TEME"}
#: WGS-84, what trackproc's stations table is geodetic on.
WGS84 = (6378137.0, 298.257223563)


class OrekitConfig:
    """The keys of one ``.in`` file: ``plain[key]`` (text) and ``indexed[key][i]`` (text)."""

    def __init__(self, plain: dict, indexed: dict, lines: dict, source: str):
        self.plain, self.indexed, self.lines, self.source = plain, indexed, lines, source

    def text(self, key: str, default=None):
        return self.plain.get(key, default)

    def number(self, key: str, default=None, index: int | None = None) -> float:
        raw = self.plain.get(key) if index is None else self.indexed.get(key, {}).get(index)
        if raw is None:
            if default is None:
                raise InputError("missing key", file=self.source, column=key if index is None else f"{key} [{index}]",
                                 expected="a number")
            return default
        try:
            value = float(raw.rstrip(";"))
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            row = self.lines.get(key if index is None else (key, index))
            raise InputError("not a number", file=self.source, row=row,
                             column=key if index is None else f"{key} [{index}]", found=raw, expected="a finite number")
        return value

    def flag(self, key: str, default: bool = False, index: int | None = None) -> bool:
        raw = self.plain.get(key) if index is None else self.indexed.get(key, {}).get(index)
        if raw is None:
            return default
        word = raw.rstrip(";").strip().lower()
        if word not in ("true", "false"):
            row = self.lines.get(key if index is None else (key, index))
            raise InputError("not a boolean", file=self.source, row=row,
                             column=key if index is None else f"{key} [{index}]", found=raw, expected="true or false")
        return word == "true"

    def station_indices(self) -> list[int]:
        return sorted(self.indexed.get("ground.station.name", {}))


def parse_orekit_config(data: bytes, source: str) -> OrekitConfig:
    """The keys of an Orekit ``.in`` file's bytes; a line that is not ``key = value`` is an error."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError("not UTF-8 text", file=source, found=repr(data[exc.start:exc.start + 8]),
                         expected="an Orekit orbit-determination configuration (key = value lines)") from None
    plain, indexed, lines = {}, {}, {}
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        if "=" not in body:
            raise InputError("not a key = value line", file=source, row=number, found=body[:60],
                             expected="key = value, or key [i] = value (Orekit .in syntax)")
        key, value = (part.strip() for part in body.split("=", 1))
        match = _INDEXED.match(key)
        if match:
            indexed.setdefault(match.group(1), {})[int(match.group(2))] = value
            lines[(match.group(1), int(match.group(2)))] = number
        else:
            plain[key] = value
            lines[key] = number
    if not plain and not indexed:
        raise InputError("no keys", file=source, expected="an Orekit orbit-determination configuration (key = value lines)")
    return OrekitConfig(plain, indexed, lines, source)


_SIGNATURE = re.compile(r"^\s*(orbit\.date|ground\.station\.name\s*\[\s*\d+\s*\])\s*=", re.M)


def looks_like_orekit_config(text: str) -> bool:
    """An Orekit orbit-determination configuration: ``orbit.date =`` or ``ground.station.name [i] =``."""
    return _SIGNATURE.search(text) is not None


def read_orekit_config(path: str) -> OrekitConfig:
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_orekit_config(read_input_bytes(path), source)


def _check_body(cfg: OrekitConfig) -> None:
    """Station coordinates are geodetic on the file's body shape: trackproc's are WGS-84."""
    radius = cfg.number("body.equatorial.radius", WGS84[0])
    flattening = cfg.number("body.inverse.flattening", WGS84[1])
    if abs(radius - WGS84[0]) > 1e-3 or abs(flattening - WGS84[1]) > 1e-6:
        raise InputError("station coordinates on another ellipsoid", file=cfg.source, column="body.equatorial.radius",
                         found=f"{radius:g} m, 1/f {flattening:.9g}", expected="WGS-84 (6378137 m, 1/f 298.257223563)")


def stations(cfg: OrekitConfig) -> list[dict]:
    """The ground stations, in the file's order: ``station, lat_deg, lon_deg, height_m`` and
    ``range_bias_m`` (the station's ``range.bias`` plus the satellite's ``onboard.range.bias``:
    Orekit adds both to every range, trackproc has one bias per station), ``range_sigma_m``,
    ``angle_sigma_deg``, and which biases Orekit estimates."""
    _check_body(cfg)
    onboard = cfg.number("onboard.range.bias", 0.0)
    out = []
    for i in cfg.station_indices():
        name = cfg.indexed["ground.station.name"][i]
        row = cfg.lines.get(("ground.station.name", i))
        lat = cfg.number("ground.station.latitude", index=i)
        lon = cfg.number("ground.station.longitude", index=i)
        height = cfg.number("ground.station.altitude", index=i)
        check_name(name, "station name", file=cfg.source, row=row, column=f"ground.station.name [{i}]")
        check_station(name, lat, lon, height, file=cfg.source, row=row)
        out.append({
            "station": name, "lat_deg": lat, "lon_deg": lon, "height_m": height,
            "range_bias_m": cfg.number("ground.station.range.bias", 0.0, index=i) + onboard,
            "range_sigma_m": cfg.number("ground.station.range.sigma", math.nan, index=i),
            "azimuth_sigma_deg": cfg.number("ground.station.azimuth.sigma", math.nan, index=i),
            "elevation_sigma_deg": cfg.number("ground.station.elevation.sigma", math.nan, index=i),
            "range_bias_estimated": cfg.flag("ground.station.range.bias.estimated", index=i),
            "angle_bias_estimated": cfg.flag("ground.station.az.el.biases.estimated", index=i),
        })
    if not out:
        raise InputError("no ground stations", file=cfg.source, column="ground.station.name [0]",
                         expected="ground.station.name [i], .latitude, .longitude, .altitude")
    return out


def initial_state(cfg: OrekitConfig) -> dict:
    """The initial orbit as a trackproc state-file document (``orbit.cartesian.*`` in
    ``inertial.frame`` at ``orbit.date``, UTC), with the spacecraft the force models switched on
    need (mass; drag area and Cd with ``drag``; SRP area and Cr with ``solar.radiation.pressure``)."""
    date = cfg.text("orbit.date")
    if date is None:
        raise InputError("missing key", file=cfg.source, column="orbit.date", expected="the initial orbit's date (UTC)")
    if not any(k.startswith("orbit.cartesian.") for k in cfg.plain):
        other = sorted({k.split(".")[1] for k in cfg.plain if k.startswith("orbit.") and k.count(".") >= 2} - {"date"})
        raise InputError("initial orbit not in Cartesian form", file=cfg.source, column="orbit.cartesian.px",
                         found=", ".join(f"orbit.{o}.*" for o in other) or "none",
                         expected="orbit.cartesian.px .. vz (the form trackproc imports)")
    frame_name = cfg.text("inertial.frame", "EME2000")
    frame = _FRAMES.get(frame_name.upper())
    if frame is None:
        raise InputError("unknown inertial frame", file=cfg.source, row=cfg.lines.get("inertial.frame"),
                         column="inertial.frame", found=frame_name, expected=", ".join(sorted(_FRAMES)))
    epoch = date if date.endswith("Z") else date + "Z"
    doc = {"epoch": epoch, "frame": frame,
           "position_m": [cfg.number(f"orbit.cartesian.p{c}") for c in "xyz"],
           "velocity_m_s": [cfg.number(f"orbit.cartesian.v{c}") for c in "xyz"]}
    spacecraft = {"mass_kg": cfg.number("mass", DEFAULT_MASS_KG)}
    if cfg.flag("drag"):
        spacecraft.update(drag_area_m2=cfg.number("drag.area"), cd=cfg.number("drag.cd"))
    if cfg.flag("solar.radiation.pressure"):
        spacecraft.update(srp_area_m2=cfg.number("solar.radiation.pressure.area"),
                          cr=cfg.number("solar.radiation.pressure.cr"))
    doc["spacecraft"] = spacecraft
    doc["comment"] = f"initial orbit of {cfg.source} (Orekit orbit-determination configuration)"
    return doc


def options(cfg: OrekitConfig, station_rows: list[dict]) -> dict:
    """trackproc defaults (config-file sections -> keys) equivalent to the file's sigmas and
    estimated biases: one value per option, so only what every station shares."""
    out: dict = {"ingest": {}, "estimate": {}}
    for key, column in (("sigma_range_m", "range_sigma_m"), ("sigma_angle_deg", "azimuth_sigma_deg")):
        values = {r[column] for r in station_rows if math.isfinite(r[column])}
        if len(values) == 1 and not (key == "sigma_range_m" and crd_measurements(cfg)):
            out["ingest"][key] = values.pop()
    if all(r["range_bias_estimated"] for r in station_rows):
        out["estimate"]["range_bias"] = True
    if all(r["angle_bias_estimated"] for r in station_rows):
        out["estimate"]["angle_bias"] = True
    com = cfg.number("range.center.of.mass.correction", 0.0)
    if com:
        out["estimate"]["com_offset"] = com
    return {k: v for k, v in out.items() if v}


def crd_measurements(cfg: OrekitConfig) -> bool:
    """The measurements are ILRS CRD normal points, whose own precision is a better range sigma
    than the file's one per station (ingest uses it unless --sigma-range-m is given)."""
    files = [f.strip().lower() for f in (cfg.text("measurements.files") or "").split(",")]
    return any(f.endswith((".npt", ".crd", ".frd")) for f in files)


#: Keys Orekit's file may switch on that the import does not carry (trackproc has them as options
#: named here, or not at all).
NOT_CARRIED = {
    "ocean.tides.degree": "ocean tides (not modelled)",
    "solid.tides.sun": "solid tides in the field (not modelled)",
    "earth.albedo.infrared": "albedo (not modelled)",
    "polynomial.acceleration.name": "estimated accelerations: estimate --estimate-force empirical-xyz",
    "onboard.range.bias.estimated": "an estimated onboard bias: per-station --range-bias absorbs it",
    "drag.cd.estimated": "estimate --estimate-force cd",
    "solar.radiation.pressure.cr.estimated": "estimate --estimate-force cr",
    "sinex.position.file": "ingest/estimate --stations FILE.snx (positions and velocities)",
    "sinex.ecc.file": "ingest --eccentricities FILE.snx",
    "measurements.files": "trackproc ingest FILE",
}


def not_carried(cfg: OrekitConfig) -> list[str]:
    """``key = value: what to use instead`` for each key the file sets that the import does not carry."""
    out = []
    for key, instead in NOT_CARRIED.items():
        raw = cfg.plain.get(key)
        if raw is None and key in cfg.indexed:
            raw = ", ".join(cfg.indexed[key][i] for i in sorted(cfg.indexed[key]))
        if raw is None or raw.rstrip(";").strip().lower() in ("false", "-1", "0", "0.0"):
            continue
        if (key == "drag.cd.estimated" and not cfg.flag("drag")) or \
                (key == "solar.radiation.pressure.cr.estimated" and not cfg.flag("solar.radiation.pressure")):
            continue                          # the force is off: nothing estimated
        out.append(f"{key} = {raw}: {instead}")
    return out
