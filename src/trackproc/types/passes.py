"""The canonical pass table in memory (:class:`PassTable`): samples and file metadata. Its columns and
metadata are described in :mod:`trackproc.io.passfile`, which reads and writes it."""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from trackproc.types.station import Station


@dataclass
class PassTable:
    """Canonical samples (``frame``, columns :data:`COLUMNS` first) and file metadata (``meta``)."""

    frame: pd.DataFrame
    meta: dict = field(default_factory=dict)

    def stations(self) -> dict:
        """Stations recorded at ingest, name -> :class:`trackproc.types.Station`."""
        source = str(self.meta.get("source") or "<pass file>")
        return {name: Station.from_meta(name, values, source)
                for name, values in (self.meta.get("stations") or {}).items()}
