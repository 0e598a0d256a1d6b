"""The intermediate form every reader produces before validation.

Readers (CSV wide/long, Parquet/Arrow, DopTrack, Orekit .aer, CCSDS TDM) each parse their own
layout and return :class:`RawMeasurements`; :mod:`trackproc.pipeline.ingest` validates it and
turns it into the canonical pass table. Keeping the source row on every sample lets
validation errors name the row the user sees in their file.
"""

from __future__ import annotations

from trackproc.types.raw import RawMeasurements  # noqa: F401  (re-exported)
#: Canonical measurement kinds and their SI unit (``value`` and ``sigma`` columns).
from trackproc.vocabulary import KIND_UNITS  # noqa: F401  (re-exported)
