"""Invalid rows of an input table, by reason: the earliest one raised as a one-line error, or all
of them dropped and counted (``--drop-invalid``). Shared by every reader and by ingest's checks."""

from __future__ import annotations

from typing import Callable

import numpy as np

from trackproc.errors import InputError

#: Reasons an invalid row is reported (or dropped with ``drop_invalid``).
UNPARSEABLE_TIME = "unparseable time"
WRONG_TYPE = "wrong column type"
UNKNOWN_KIND = "unknown kind"
NONFINITE_VALUE = "non-finite value"
NONFINITE_SIGMA = "non-finite sigma"

TIME_EXPECTED = "an ISO 8601 UTC time such as 2020-04-01T08:44:03.29Z (years 1678-2261)"


# --------------------------------------------------------------------------- invalid rows


class Problems:
    """Invalid rows of a table, by reason: raise the earliest one, or drop them all.

    ``rows`` are the 1-based source rows shown in messages, ``files`` the source of each row (one
    name, or an array when several files were merged); ``order`` sorts rows for "earliest"
    (defaults to ``rows``). Each :meth:`add` takes a boolean mask over the rows and, per row,
    the column, the value found and the expected form (a scalar, an array, or a callable of the
    row position).
    """

    def __init__(self, rows, files, order=None):
        self.rows = np.asarray(rows)
        self.files = files
        self.order = self.rows if order is None else np.asarray(order)
        self._checks: list[tuple] = []

    def add(self, reason: str, mask, *, column, found, expected, detail="") -> None:
        mask = np.asarray(mask, dtype=bool)
        if mask.any():
            self._checks.append((reason, mask, column, found, expected, detail))

    def __bool__(self) -> bool:
        return bool(self._checks)

    def invalid(self) -> np.ndarray:
        """True for every row with at least one problem so far."""
        bad = np.zeros(len(self.rows), dtype=bool)
        for check in self._checks:
            bad |= check[1]
        return bad

    def first_error(self) -> InputError | None:
        best = None
        for check in self._checks:
            positions = np.flatnonzero(check[1])
            pos = int(positions[np.argmin(self.order[positions])])
            if best is None or self.order[pos] < self.order[best[0]]:
                best = (pos, check)
        if best is None:
            return None
        pos, (reason, _, column, found, expected, detail) = best
        pick = _picker(pos)
        return InputError(pick(detail) or reason, file=pick(self.files), row=int(self.rows[pos]),
                          column=pick(column), found=_plain(pick(found)), expected=pick(expected))

    def resolve(self, drop_invalid: bool) -> tuple[np.ndarray, dict[str, int]]:
        """Rows to keep and, per reason, how many rows were dropped (each counted once)."""
        keep = np.ones(len(self.rows), dtype=bool)
        if not self._checks:
            return keep, {}
        if not drop_invalid:
            raise self.first_error()
        counts: dict[str, int] = {}
        for reason, mask, *_ in self._checks:
            newly = mask & keep
            if newly.any():
                counts[reason] = counts.get(reason, 0) + int(newly.sum())
            keep &= ~mask
        return keep, counts


def _picker(pos: int) -> Callable[[object], object]:
    def pick(item):
        if callable(item):
            return item(pos)
        if hasattr(item, "iloc"):           # a pandas Series (not imported here: start-up)
            return item.iloc[pos]
        if isinstance(item, (np.ndarray, list, tuple)):
            return item[pos]
        return item
    return pick


def _plain(value):
    """numpy scalars shown as Python values in messages."""
    return value.item() if isinstance(value, np.generic) else value


def add_counts(total: dict[str, int], more: dict[str, int]) -> dict[str, int]:
    for reason, n in more.items():
        total[reason] = total.get(reason, 0) + n
    return total
