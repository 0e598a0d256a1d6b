"""Samples as a reader found them (:class:`RawMeasurements`): long form, SI units, not yet validated
(see :mod:`trackproc.io.raw`)."""

from __future__ import annotations

from typing import Optional


class RawMeasurements:
    """Samples in long form, SI units, not yet validated.

    ``frame`` (a pandas DataFrame) has the columns ``time`` (datetime64[ns, UTC]),
    ``station`` (str), ``kind`` (one of :data:`KIND_UNITS`), ``value`` (float64, SI),
    ``sigma`` (float64, NaN where the source gives none) and ``row`` (int, the 1-based row
    or line in the source as an editor or spreadsheet shows it), and optionally ``pass_id``.
    ``column`` maps each kind to the source column it came from, for error messages.
    ``meta`` carries file-level facts: ``carrier_hz``, ``doppler_mode``, ``stations``
    (name -> {lat_deg, lon_deg, height_m}) when the source defines them, ``source``.

    A reader may give ``arrays`` instead of ``frame``: the same columns as numpy arrays (``time``
    datetime64[ns] in UTC, the text columns object arrays of str); ``frame`` is then built from
    them when first asked for (and is the truth from then on). Ingest reads the arrays directly (no
    DataFrame: with pandas 3 its string columns would become Arrow strings and back).
    """

    def __init__(self, frame=None, source: str = "", column: Optional[dict] = None, meta: Optional[dict] = None,
                 arrays: Optional[dict] = None):
        self._frame = frame
        self.source = source
        self.column = {} if column is None else column
        self.meta = {} if meta is None else meta
        self.arrays = arrays

    @property
    def frame(self):
        """The samples as a DataFrame, built from :attr:`arrays` when first read. Once handed out it
        is the truth (a caller may change it in place): the arrays are dropped, and ingest reads
        the frame from then on."""
        if self._frame is None and self.arrays is not None:
            self._frame = frame_of_arrays(self.arrays)
        self.arrays = None
        return self._frame

    @frame.setter
    def frame(self, value) -> None:
        self._frame, self.arrays = value, None

    def size(self) -> int:
        """The number of samples (without building the frame)."""
        return len(self.arrays["row"]) if self.arrays is not None else len(self.frame)

    def __repr__(self) -> str:
        return f"RawMeasurements(source={self.source!r}, samples={self.size()}, column={self.column!r})"


#: The columns of a reader's frame, in order (``pass_id`` when the input has it).
FRAME_COLUMNS = ("time", "station", "kind", "value", "sigma", "row", "unit", "pass_id")


def frame_of_arrays(arrays: dict):
    """The DataFrame of :attr:`RawMeasurements.arrays` (the frame the readers built before)."""
    import pandas as pd  # only when a caller wants the frame (info, the ingest command's summary)

    columns = {name: arrays[name] for name in FRAME_COLUMNS if name in arrays}
    columns["time"] = pd.DatetimeIndex(columns["time"]).tz_localize("UTC")
    return pd.DataFrame(columns)
