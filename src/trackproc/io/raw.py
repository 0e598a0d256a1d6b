"""The intermediate form every reader produces before validation.

Readers (CSV wide/long, Parquet/Arrow, DopTrack, Orekit .aer, CCSDS TDM) each parse their own
layout and return :class:`RawMeasurements`; :mod:`trackproc.pipeline.ingest` validates it and
turns it into the canonical pass table. Keeping the source row on every sample lets
validation errors name the row the user sees in their file.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: Canonical measurement kinds and their SI unit (``value`` and ``sigma`` columns).
from trackproc.vocabulary import KIND_UNITS  # noqa: F401  (re-exported)


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
