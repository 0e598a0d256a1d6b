"""Samples as a reader found them (:class:`RawMeasurements`): long form, SI units, not yet validated
(see :mod:`trackproc.io.raw`)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class RawMeasurements:
    """Samples in long form, SI units, not yet validated.

    ``frame`` (a pandas DataFrame) has the columns ``time`` (datetime64[ns, UTC]),
    ``station`` (str), ``kind`` (one of :data:`KIND_UNITS`), ``value`` (float64, SI),
    ``sigma`` (float64, NaN where the source gives none) and ``row`` (int, the 1-based row
    or line in the source as an editor or spreadsheet shows it), and optionally ``pass_id``.
    ``column`` maps each kind to the source column it came from, for error messages.
    ``meta`` carries file-level facts: ``carrier_hz``, ``doppler_mode``, ``stations``
    (name -> {lat_deg, lon_deg, height_m}) when the source defines them, ``source``.
    """

    frame: object
    source: str
    column: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
