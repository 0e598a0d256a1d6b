"""The checks ``ingest`` makes of each sample on its own (value, sigma, domains, plausible
speeds) and of the Doppler link settings (carrier and mode, from the options or the inputs):
every violation an :class:`~trackproc.errors.InputError` naming file, row and column, or, with
``drop_invalid``, a dropped sample counted by reason (:class:`~trackproc.io.problems.Problems`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

from trackproc.errors import InputError
from trackproc.io.layouts import UNIT_SPELLINGS
from trackproc.io.passfile import KINDS
from trackproc.io.raw import KIND_UNITS
from trackproc.io.problems import NONFINITE_SIGMA, NONFINITE_VALUE, UNKNOWN_KIND, Problems
from trackproc.io.raw import RawMeasurements
from trackproc.io.validate import MAX_LOS_SPEED_M_S, check_carrier, check_los_speed
from trackproc.pipeline.ingest_samples import Samples, factorize

if TYPE_CHECKING:
    from trackproc.pipeline.ingest import IngestOptions

NONPOSITIVE_SIGMA = "non-positive sigma"
TINY_SIGMA = "sigma below the floor"
#: Smallest sigma accepted per kind (SI): far below any tracking system (laser normal points reach
#: ~1 mm, deep-space Doppler ~0.05 mm/s and 0.1 mHz, optical angles ~0.05 arcsec = 2.4e-7 rad); a
#: smaller one is a unit mistake or a placeholder, and its weight 1/sigma^2 would swamp every
#: other sample (1e-300 overflows to inf).
SIGMA_FLOOR = {"range": 1e-6, "range_rate": 1e-8, "doppler": 1e-6, "elevation": 1e-10, "azimuth": 1e-10}
ELEVATION_RANGE = "elevation out of range"
NEGATIVE_RANGE = "negative range"
AZIMUTH_RANGE = "azimuth out of range"
RANGE_RATE_SPEED = "implausible range-rate"
#: Unit as written -> factor to SI (to report values as the user wrote them).
UNIT_FACTORS = {unit: factor for _, factor, unit in UNIT_SPELLINGS.values()}


def unit_factors(units: np.ndarray) -> np.ndarray:
    """Per sample, the factor from the unit the file used to SI (1 where unknown)."""
    codes, uniques = factorize(units)   # one lookup per distinct unit
    factors = np.array([UNIT_FACTORS.get(u, 1.0) if isinstance(u, str) else 1.0 for u in uniques] + [1.0],
                       dtype=np.float64)
    return factors[codes]                                                # code -1 (missing): the last, 1


def sample_problems(frame) -> Problems:
    """The checks of each sample on its own (value, sigma, domains) over one chunk of one input
    (:class:`trackproc.pipeline.ingest.Chunk`: numpy columns by name)."""
    problems = Problems(frame["row"], frame["source"])
    kind = frame["kind"]
    value = frame["value"]
    sigma = frame["sigma"]
    units = frame["unit"]
    factors = unit_factors(units)
    value_written, sigma_written = value / factors, sigma / factors
    value_col = frame["value_column"]
    sigma_col = frame["sigma_column"]

    codes, kinds = factorize(kind)   # one lookup per distinct kind (-1 for a missing one)
    # np.isin(kind, KINDS) by the distinct kinds (np.isin sorts the objects: ~3x the time)
    known = np.array([k in KINDS for k in kinds] + [False], dtype=bool)[codes]
    problems.add(UNKNOWN_KIND, ~known, column="kind", found=kind,
                 expected="one of " + ", ".join(KINDS))
    problems.add(NONFINITE_VALUE, ~np.isfinite(value), column=value_col, found=value_written,
                 expected="a finite number")
    problems.add(NONFINITE_SIGMA, ~np.isfinite(sigma), column=sigma_col, found=sigma_written,
                 expected="a finite sigma > 0")
    problems.add(NONPOSITIVE_SIGMA, sigma <= 0, column=sigma_col, found=sigma_written,
                 expected="sigma > 0")
    floor = np.array([SIGMA_FLOOR.get(k, 0.0) for k in kinds] + [0.0], dtype=np.float64)[codes]
    problems.add(TINY_SIGMA, (sigma > 0) & (sigma < floor), column=sigma_col, found=sigma_written,
                 expected=lambda i: (f"sigma >= {floor[i]:g} {KIND_UNITS.get(kind[i], '')} (SI) for {kind[i]}; "
                                     "smaller is no tracking system's precision"))
    elevation = (kind == "elevation") & np.isfinite(value)
    in_deg = units == "deg"
    problems.add(ELEVATION_RANGE, elevation & (np.abs(value) > math.pi / 2 + 1e-12), column=value_col,
                 found=value_written,
                 expected=lambda i: ("an elevation in [-90, 90] deg" if in_deg[i]
                                     else "an elevation in [-pi/2, pi/2] rad"))
    finite = np.isfinite(value)
    problems.add(NEGATIVE_RANGE, finite & (kind == "range") & (value < 0), column=value_col, found=value_written,
                 expected="a range >= 0")
    problems.add(AZIMUTH_RANGE, finite & (kind == "azimuth") & ((value < -math.pi) | (value > 2 * math.pi)),
                 column=value_col, found=value_written,
                 expected=lambda i: ("an azimuth in [-180, 360] deg" if in_deg[i]
                                     else "an azimuth in [-pi, 2 pi] rad"))
    problems.add(RANGE_RATE_SPEED, finite & (kind == "range_rate") & (np.abs(value) > MAX_LOS_SPEED_M_S),
                 column=value_col, found=value_written,
                 expected=f"|range-rate| <= {MAX_LOS_SPEED_M_S / 1000:g} km/s (an Earth orbit); is the unit right?")
    return problems


def doppler_settings(raws: Sequence[RawMeasurements], samples: Samples, options: IngestOptions):
    """Carrier (Hz) and mode from the options or the inputs; required with Doppler samples."""
    settings = {}
    for key, option, flag in (("carrier_hz", options.carrier_hz, "--carrier-hz"),
                              ("doppler_mode", options.doppler_mode, "--mode")):
        value = option
        for raw in raws:
            given = raw.meta.get(key)
            if given is None:
                continue
            if value is None:
                value = given
            elif not same_setting(value, given):
                raise InputError(f"conflicting {key}", file=raw.source, column=flag, found=given,
                                 expected=f"{value} as {'given by ' + flag if option is not None else 'in the other inputs'}")
        settings[key] = value
    c = samples.columns
    doppler = np.flatnonzero(c["kind"] == KINDS.index("doppler"))   # in arrival order
    if doppler.size:
        first = int(doppler[0])
        where = {"file": raws[c["input"][first]].source, "row": int(c["row"][first])}
        if settings["carrier_hz"] is None:
            raise InputError("Doppler samples need the nominal carrier frequency", column="--carrier-hz",
                             expected="--carrier-hz F (Hz)", **where)
        if settings["doppler_mode"] is None:
            raise InputError("Doppler samples need the link mode", column="--mode",
                             expected="--mode one-way or --mode two-way", **where)
    carrier = settings["carrier_hz"]
    if carrier is not None:
        carrier = check_carrier(carrier, column="--carrier-hz" if options.carrier_hz is not None else "carrier_hz")
        sources = np.array([raw.source for raw in raws], dtype=object)[c["input"][doppler]]
        for source in dict.fromkeys(sources.tolist()):   # in order of first appearance
            mine = doppler[sources == source]
            check_los_speed(c["value"][mine], "doppler", carrier_hz=carrier, mode=settings["doppler_mode"],
                            file=source, rows=c["row"][mine],
                            column=str(raws[c["input"][mine[0]]].column.get("doppler", "value")))
    return carrier, settings["doppler_mode"]


def same_setting(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return abs(a - b) <= 1e-12 * max(abs(a), abs(b))
    return a == b
