"""The nominal trajectory of ``trackproc detect`` (NOMINAL.json, see :mod:`trackproc.pipeline.detect`):
:class:`Nominal` and its reader.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.isotime import iso_utc
from trackproc.methods.ballistic import R_PLANAR
from trackproc.types import parse_epoch
from trackproc.types.checks import check_name
from trackproc.vocabulary import EARTHS, TAYLOR_FORCES


DEG = math.pi / 180.0
MODELS = ("planar", "3d")
FIELDS = ("impact_time", "velocity_kms", "velocity_m_s", "angle_deg", "p_m", "e", "phi_deg", "model",
          "displacement_m", "station", "pass_id", "direction", "latitude_deg", "heading_deg", "radius_m",
          "sigma_rad", "tau_s", "force", "earth", "kinds", "comment", "schema_version")


@dataclass(frozen=True)
class Nominal:
    """The nominal trajectory of NOMINAL.json (SI units; see the module docstring)."""

    impact_time: np.datetime64
    model: str = "planar"
    velocity_m_s: Optional[float] = None
    angle_rad: Optional[float] = None
    p_m: Optional[float] = None
    e: Optional[float] = None
    phi_rad: Optional[float] = None
    displacement_m: float = 500.0
    station: Optional[str] = None
    pass_id: Optional[str] = None
    direction: str = "none"
    latitude_deg: Optional[float] = None
    heading_deg: Optional[float] = None
    radius_m: Optional[float] = None
    sigma_rad: Optional[float] = None
    tau_s: float = 0.0
    force: str = "two-body"
    earth: str = "wgs84"
    kinds: Optional[tuple] = None
    source: str = "<nominal>"

    def describe(self) -> dict:
        """JSON-ready echo (angles in degrees, time ISO)."""
        out = {"impact_time": iso_utc(self.impact_time), "model": self.model,
               "displacement_m": self.displacement_m, "direction": self.direction, "tau_s": self.tau_s}
        if self.velocity_m_s is not None:
            out.update(velocity_m_s=self.velocity_m_s, angle_deg=self.angle_rad / DEG)
        if self.p_m is not None:
            out.update(p_m=self.p_m, e=self.e)
        if self.phi_rad is not None:
            out["phi_deg"] = self.phi_rad / DEG
        for key in ("station", "pass_id", "latitude_deg", "heading_deg", "radius_m", "sigma_rad"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.model == "3d":
            out.update(force=self.force, earth=self.earth)
        if self.kinds is not None:
            out["kinds"] = list(self.kinds)
        return out


def read_nominal(path: str) -> Nominal:
    """Read and check NOMINAL.json (``-`` = stdin)."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_nominal(read_input_bytes(path), source)


@dataclass(frozen=True)
class _Fields:
    """The fields of one NOMINAL.json document, read with checks that name ``source`` and the field."""

    doc: dict
    source: str

    def number(self, key, *, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False, expected=None):
        """The finite number at ``key`` within the bounds, or None when absent."""
        if key not in self.doc or self.doc[key] is None:
            return None
        value = self.doc[key]
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if ok:
            value = float(value)
            ok = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
        if not ok:
            raise InputError("invalid value", file=self.source, column=key, found=self.doc[key],
                             expected=expected or f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}"
                                                  f"{')' if hi_open else ']'}")
        return value

    def choice(self, key, options, default):
        """One of ``options`` (case and blanks ignored), ``default`` when absent."""
        value = self.doc.get(key, default)
        if value is None:
            value = default
        if not isinstance(value, str) or value.strip().lower() not in options:
            raise InputError("invalid value", file=self.source, column=key, found=value,
                             expected=" or ".join(options))
        return value.strip().lower()

    def text(self, key):
        """A non-empty name, or None when absent."""
        value = self.doc.get(key)
        if value is None:
            return None
        if not isinstance(value, str) or not value.strip():
            raise InputError("invalid value", file=self.source, column=key, found=value,
                             expected="a non-empty string")
        return check_name(value.strip(), key.replace("_", " "), file=self.source, column=key)

    def missing(self, key, expected):
        return InputError("missing field", file=self.source, column=key, expected=expected)


@dataclass(frozen=True)
class _Trajectory:
    """The trajectory as given: by the impact (speed, angle) or by the conic (p, e, φ); SI units,
    angles in degrees as in the file."""

    velocity_m_s: Optional[float]
    angle_deg: Optional[float]
    p_m: Optional[float]
    e: Optional[float]
    phi_deg: Optional[float]
    radius_m: Optional[float]


def _document(data: bytes | str, source: str) -> _Fields:
    """The JSON object of ``data`` with only known fields."""
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid JSON ({getattr(exc, 'msg', exc)})", file=source,
                         row=getattr(exc, "lineno", None), expected="a JSON object (NOMINAL.json)") from None
    except RecursionError:
        raise InputError("JSON nested too deeply", file=source, expected="a JSON object (NOMINAL.json)") from None
    if not isinstance(doc, dict):
        raise InputError("not a nominal-trajectory file", file=source, found=type(doc).__name__,
                         expected="a JSON object")
    unknown = sorted(k for k in doc if k not in FIELDS)
    if unknown:
        raise InputError("unknown field", file=source, column=unknown[0], expected="one of " + ", ".join(FIELDS))
    return _Fields(doc, source)


def _trajectory(f: _Fields, model: str) -> _Trajectory:
    """Exactly one of the two ways to give the trajectory, complete, and a conic that reaches
    the Earth's surface (seed 003: e >= |1 - p/R|)."""
    source = f.source
    v_kms = f.number("velocity_kms", lo=0, hi=7.9, lo_open=True, hi_open=True,
                     expected="an impact speed in km/s in (0, 7.9) (sub-orbital)")
    v_ms = f.number("velocity_m_s", lo=0, hi=7900, lo_open=True, hi_open=True,
                    expected="an impact speed in m/s in (0, 7900) (sub-orbital)")
    if v_kms is not None and v_ms is not None:
        raise InputError("give the speed once", file=source, column="velocity_m_s",
                         expected="either velocity_kms or velocity_m_s")
    velocity = v_ms if v_ms is not None else (v_kms * 1000.0 if v_kms is not None else None)
    angle = f.number("angle_deg", lo=0, hi=90, lo_open=True, hi_open=True,
                     expected="the flight-path angle below the horizontal, degrees in (0, 90)")
    p_m = f.number("p_m", lo=0, lo_open=True, expected="the focal parameter in metres, > 0")
    ecc = f.number("e", lo=0, hi=1, hi_open=True, expected="the eccentricity in [0, 1)")
    phi = f.number("phi_deg", lo=-360, hi=360, expected="degrees in [-360, 360]")
    by_impact = velocity is not None or angle is not None
    by_conic = p_m is not None or ecc is not None
    if by_impact and by_conic:
        raise InputError("give the trajectory once", file=source, column="p_m",
                         expected="either velocity_kms/velocity_m_s + angle_deg, or p_m + e (+ phi_deg)")
    if by_impact and (velocity is None or angle is None):
        raise f.missing("angle_deg" if angle is None else "velocity_kms", "both the impact speed and angle_deg")
    if by_conic and (p_m is None or ecc is None):
        raise f.missing("e" if ecc is None else "p_m", "both p_m and e")
    if not (by_impact or by_conic):
        raise f.missing("velocity_kms", "velocity_kms (or velocity_m_s) and angle_deg, or p_m and e")
    if model == "3d" and not by_impact:
        raise InputError("the 3-D model needs the impact speed and angle", file=source, column="velocity_kms",
                         expected="velocity_kms (or velocity_m_s) and angle_deg")
    if phi is not None and not by_conic:
        raise InputError("phi_deg goes with p_m and e", file=source, column="phi_deg",
                         expected="no phi_deg with velocity/angle (the unfavourable orbit φ = θ_f is used)")
    radius = f.number("radius_m", lo=6.0e6, hi=7.0e6, expected="an Earth radius in metres in [6.0e6, 7.0e6]")
    if by_conic:
        r_model = radius or R_PLANAR
        if ecc < abs(1.0 - p_m / r_model):
            raise InputError("the orbit does not reach the Earth's surface", file=source, column="e", found=ecc,
                             expected=f"e >= |1 - p/R| = {abs(1.0 - p_m / r_model):.6g}")
    return _Trajectory(velocity, angle, p_m, ecc, phi, radius)


def _flight_direction(f: _Fields, model: str) -> tuple[str, Optional[float]]:
    """``direction`` and ``heading_deg``: the 3-D model needs one of them, the planar one no heading."""
    direction = f.choice("direction", ("with", "against", "none"), "none")
    heading = f.number("heading_deg", lo=0, hi=360, hi_open=True, expected="degrees in [0, 360)")
    if model == "3d" and direction == "none" and heading is None:
        raise InputError("the 3-D model needs the direction of flight", file=f.source, column="direction",
                         expected="with or against (or heading_deg)")
    if heading is not None and model != "3d":
        raise InputError("heading_deg is for the 3-D model", file=f.source, column="heading_deg",
                         expected="model = \"3d\", or direction with/against")
    return direction, heading


def _kinds(f: _Fields, model: str) -> Optional[tuple]:
    """The kinds the file asks for (elevation, and azimuth for the 3-D model), or None."""
    kinds = f.doc.get("kinds")
    if kinds is None:
        return None
    if (not isinstance(kinds, list) or not kinds or any(k not in ("elevation", "azimuth") for k in kinds)
            or "elevation" not in kinds):
        raise InputError("invalid value", file=f.source, column="kinds", found=kinds,
                         expected='["elevation"] or ["elevation", "azimuth"]')
    if model == "planar" and "azimuth" in kinds:
        raise InputError("the planar model predicts elevation only", file=f.source, column="kinds",
                         found=kinds, expected='["elevation"] (or model "3d")')
    return tuple(k for k in ("elevation", "azimuth") if k in kinds)


def parse_nominal(data: bytes | str, source: str = "<nominal>") -> Nominal:
    """The :class:`Nominal` in the JSON text ``data``; errors name ``source`` and the field
    (checked in a fixed order, so a file with several faults always names the same one)."""
    f = _document(data, source)
    if "impact_time" not in f.doc:
        raise f.missing("impact_time", "the impact time T, ISO 8601 UTC (e.g. 2026-03-20T10:00:00Z)")
    impact = parse_epoch(f.doc["impact_time"], file=source, column="impact_time")
    model = f.choice("model", MODELS, "planar")
    trajectory = _trajectory(f, model)
    displacement = f.number("displacement_m", expected="a displacement in metres")
    if displacement is not None and displacement == 0:
        raise InputError("invalid value", file=source, column="displacement_m", found=0,
                         expected="a non-zero displacement Δ* in metres")
    direction, heading = _flight_direction(f, model)
    kinds = _kinds(f, model)
    angle, phi = trajectory.angle_deg, trajectory.phi_deg
    return Nominal(
        impact_time=impact, model=model, velocity_m_s=trajectory.velocity_m_s,
        angle_rad=None if angle is None else angle * DEG,
        p_m=trajectory.p_m, e=trajectory.e, phi_rad=None if phi is None else phi * DEG,
        displacement_m=500.0 if displacement is None else displacement,
        station=f.text("station"), pass_id=f.text("pass_id"), direction=direction,
        latitude_deg=f.number("latitude_deg", lo=-90, hi=90, expected="degrees in [-90, 90]"),
        heading_deg=heading, radius_m=trajectory.radius_m,
        sigma_rad=f.number("sigma_rad", lo=0, hi=0.5, lo_open=True, expected="a sigma in rad in (0, 0.5]"),
        tau_s=f.number("tau_s", lo=0, expected="a reaction time in s, >= 0") or 0.0,
        force=f.choice("force", TAYLOR_FORCES, "two-body"), earth=f.choice("earth", EARTHS, "wgs84"),
        kinds=kinds, source=source)
