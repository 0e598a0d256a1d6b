"""``trackproc smooth``: least-squares generalized-polynomial smoothing of every pass (seed 004 eq. 1).

Each (station, pass_id, kind) group of the canonical pass table is fitted on its own by
:func:`trackproc.methods.smoothing.smooth_pass` (Chebyshev or Legendre basis on the pass interval
mapped to [-1, 1]; fixed degree or BIC-selected; iterative K-sigma rejection with a robust scale).
For range-rate, range and Doppler the time of closest approach (TCA) follows from the fitted curve
(:func:`trackproc.methods.smoothing.closest_approach`); for one-way Doppler also the carrier at
closest approach ``fca = carrier_hz + doppler(tca)``.

Status of each fit, in the summary and the metadata:

- ``ok``: fitted, no warning;
- ``suspect``: fitted, with warnings: ``tca_not_observed`` (no TCA inside the pass, or it falls
  in a data gap longer than ``tca_max_gap_s`` or closer than that to either end of the data, so
  it would be an interpolation or extrapolation of the polynomial), ``tca_uncertain`` (the TCA
  moves over neighbouring degrees by more than ``TCA_SPREAD_RATIO`` times its formal sigma: the
  curve, not the noise, limits it; or the noise is ``curve_unresolved``; ``tca.status = uncertain``), ``largest_gap`` (one data gap
  covers more than half of the pass), ``curve_unresolved`` (the residuals are correlated, but
  correlated noise and curve the polynomial does not follow cannot be told apart with these
  samples: the noise is taken as white and the sigmas may be too small), ``many_rejected`` (more than 10 % of the samples exceed the
  rejection threshold: only the worst 10 % are flagged, the rest kept), ``clip_not_converged``
  (the rejected set kept changing);
- ``failed``: not fitted (too few points for the degree, a single time, too few left after
  rejection, rank deficient); the other passes proceed.

:func:`smooth` raises :class:`~trackproc.errors.ProcessingError` only when no fit succeeded.

Azimuth is unwrapped before the fit (a pass through north jumps by 2 pi), so its coefficients
describe the continuous angle; ``smoothed`` and grid values are wrapped back to [0, 2 pi) and
residuals are the wrapped differences.

A little over 400 lines: the pass table in, the fits per group and the smoothed table out, from a
DataFrame or from numpy columns (the batch's path, without pandas) in the same module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import chain
from typing import Sequence

import numpy as np

from trackproc.pipeline.plotting import require_matplotlib  # noqa: F401  (re-exported for the CLI)
from trackproc.io.jsonutil import json_ready
from trackproc.errors import InputError, ProcessingError
from trackproc.io.passfile import KINDS, PassTable
from trackproc.pipeline.smooth_summary import (GRID_NOTE, TCA_KINDS, at_offset, grid_of, iso,
                                              summary_json, summary_of)  # noqa: F401  (summary_json re-exported)
from trackproc.methods.smoothing import (DEFAULT_MAX_DEGREE, ClosestApproach, PolynomialFit, SmoothingError,
                                         TCA_SPREAD_RATIO, closest_approach, degree_spread_width,
                                         smooth_pass, tca_degree_spread, tca_uncertain)

#: Default limits of the TCA observability check and of the per-pass warnings.
DEFAULT_TCA_MAX_GAP_S = 30.0
LARGEST_GAP_FRACTION = 0.5
#: Columns added to the sample table.
ADDED_COLUMNS = ("smoothed", "residual", "flag")



@dataclass
class SmoothOptions:
    """Options of ``trackproc smooth``.

    ``degree``: an integer >= 0 or ``"auto"``; ``clip``: K (None or 0 = no rejection);
    ``kinds``: kinds to fit (None = all present); ``grid_step_s``: write the curve every STEP
    seconds instead of at the samples; ``tca_max_gap_s``: longest data gap (s) allowed around the
    TCA, and shortest data span on each side of it.
    """

    degree: int | str = "auto"
    clip: float | None = 4.0
    kinds: Sequence[str] | None = None
    basis: str = "chebyshev"
    max_degree: int = DEFAULT_MAX_DEGREE
    grid_step_s: float | None = None
    tca_max_gap_s: float = DEFAULT_TCA_MAX_GAP_S


@dataclass
class PassFit:
    """The fit of one station, pass and kind (``fit`` None when it failed)."""

    station: str
    pass_id: str
    kind: str
    rows: np.ndarray                      # positions in the input frame
    epoch_utc: np.datetime64              # t = 0 of the polynomial (first sample), UTC datetime64[ns]
    t_s: np.ndarray                       # sample times, s from epoch
    status: str = "ok"                    # ok | suspect | failed
    error: str | None = None
    reason: str | None = None
    fit: PolynomialFit | None = None
    tca: ClosestApproach | None = None
    tca_error: str | None = None          # why the TCA is not observed, or uncertain
    tca_gap_s: float | None = None
    tca_spread: tuple = (float("nan"), float("nan"), 0)   # (s, value unit, degrees) over degree +- 2
    warnings: list = field(default_factory=list)

    @property
    def epoch(self):
        """:attr:`epoch_utc` as a UTC ``pd.Timestamp`` (pandas imported only by who asks)."""
        import pandas as pd

        return pd.Timestamp(self.epoch_utc).tz_localize("UTC")

    @property
    def label(self) -> str:
        return f"{self.station}/{self.pass_id}/{self.kind}"


@dataclass
class SmoothResult:
    """``table``: what ``-o`` receives (samples with smoothed/residual/flag, or the grid);
    ``samples``: always the sample table; ``summary``: the JSON summary (also in the metadata)."""

    table: PassTable
    samples: PassTable
    fits: list[PassFit]
    summary: dict

    @property
    def failed(self) -> list[PassFit]:
        return [f for f in self.fits if f.status == "failed"]

    @property
    def suspect(self) -> list[PassFit]:
        return [f for f in self.fits if f.status == "suspect"]


def smooth(table: PassTable, options: SmoothOptions | None = None, *, source: str | None = None) -> SmoothResult:
    """Fit every (station, pass, kind) of ``table``; see the module docstring for the statuses."""
    options = options or SmoothOptions()
    _check_options(options)
    # a table of numpy columns (a pass file read, ingest's) is smoothed without its DataFrame
    source_columns = _numpy_columns(table)
    if source_columns is not None:
        frame = None
        n_rows = len(source_columns["time"])
        kind_column = source_columns["kind"]
    else:
        frame = _without_added(table.frame)
        n_rows = len(frame)
        kind_column = frame["kind"].to_numpy()
    present = sorted(set(kind_column.tolist()) if frame is None else frame["kind"].unique())
    kinds = list(options.kinds) if options.kinds else present
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise InputError("unknown kind", column="--kinds", found=", ".join(unknown),
                         expected="one or more of " + ", ".join(KINDS))
    chosen = [k for k in kinds if k in present]
    if not chosen:
        raise InputError("no samples of the requested kinds", file=source, column="kind",
                         found=", ".join(present) or "no samples", expected=", ".join(kinds))
    _check_sigma(source_columns["sigma"] if frame is None else frame["sigma"].to_numpy(dtype=float), kind_column,
                 lambda: _without_added(table.frame) if frame is None else frame, chosen, source)

    doppler_mode = str(table.meta.get("doppler_mode") or "one-way")
    carrier_hz = table.meta.get("carrier_hz")
    fits = []
    # the groups' rows only (no frame per group), the columns as numpy once
    if frame is None:
        columns = _Columns.of_numpy(source_columns)
        keys = {c: source_columns[c] for c in ("station", "pass_id", "kind")}
    else:
        columns = _Columns(frame)
        keys = {c: frame[c].to_numpy() for c in ("station", "pass_id", "kind")}
    groups = _group_rows((lambda: _without_added(table.frame)) if frame is None else frame, chosen, keys)
    for station, pass_id, kind in sorted(groups):
        fits.append(_fit_group(columns, groups[(station, pass_id, kind)], str(station), str(pass_id),
                               str(kind), options, doppler_mode))

    if all(f.status == "failed" for f in fits):
        details = "; ".join(f"{f.label}: {f.error}" for f in fits)
        raise ProcessingError(f"no pass could be fitted ({len(fits)} tried): {details}",
                              {"failed": [f.label for f in fits]})

    smoothed = np.full(n_rows, np.nan)
    residual = np.full(n_rows, np.nan)
    flag = np.zeros(n_rows, bool)
    for f in fits:
        if f.fit is None:
            flag[f.rows] = True
            continue
        residual[f.rows] = f.fit.residual
        smoothed[f.rows] = f.fit(f.t_s)
        if f.kind == "azimuth":
            smoothed[f.rows] = np.mod(smoothed[f.rows], 2 * np.pi)
        flag[f.rows] = ~f.fit.used
    added_columns = {"smoothed": smoothed, "residual": residual, "flag": flag}
    if frame is not None:
        samples = _with_added(frame, added_columns)

    summary = _summary_ready(summary_of(fits, options, table.meta, source, doppler_mode, carrier_hz))
    meta = dict(table.meta)
    meta["smoothing"] = summary
    sample_meta = {**meta, "smoothing": {**summary, "output": "samples"}}
    if frame is None:
        sample_table = PassTable.from_columns({**source_columns, **added_columns}, sample_meta,
                                              lambda: _with_added(_without_added(table.frame), added_columns))
    else:
        known = {**columns.known(), "flag": flag}
        # the key columns as PassTable.column gives them when every entry is a string (``astype(str)``
        # changes nothing then)
        known.update({c: v for c, v in keys.items() if v.dtype == object and set(map(type, v)) == {str}})
        sample_table = _column_table(samples, sample_meta, known)
    if options.grid_step_s is None:
        out = sample_table
    else:
        grid_meta = {**meta, "smoothing": {**summary, "output": "grid", "grid_step_s": options.grid_step_s,
                                           "grid_note": GRID_NOTE}}
        out = PassTable(grid_of(fits, options.grid_step_s), grid_meta)
    return SmoothResult(table=out, samples=sample_table, fits=fits, summary=summary)


# --------------------------------------------------------------------------- internals


#: The columns the steps after smoothing read (refine's pass selection and samples, batch's
#: numbers): converted from the frame once, not at every ``PassTable.column`` call (~20 a refinement).
_READ_COLUMNS = ("time", "station", "pass_id", "kind", "value", "sigma", "flag")


#: A fit record's float lists (``tolist()`` of the fit's arrays: Python floats), most of its numbers.
_FLOAT_LISTS = frozenset(("coefficients", "covariance_unscaled", "covariance_scaled"))
_LIST_TYPE, _FLOAT_TYPE = {list}, {float}


def _summary_ready(summary: dict) -> dict:
    """``json_ready(summary)``, the same value and key order, with the records' float lists
    taken as they are when they hold only finite Python floats (``json_ready`` would copy them
    unchanged, walking each float in Python)."""
    fits = summary.get("fits")
    if type(fits) is not list or not all(type(rec) is dict for rec in fits):
        return json_ready(summary)
    rest = json_ready({k: v for k, v in summary.items() if k != "fits"})
    records = [{str(k): v if k in _FLOAT_LISTS and _finite_floats(v) else json_ready(v) for k, v in rec.items()}
               for rec in fits]
    return {str(k): records if k == "fits" else rest[str(k)] for k in summary}


def _finite_floats(values) -> bool:
    """A list of finite floats, or a list of such lists (their sum is finite only when each is:
    a NaN or an infinity stays in it; a sum that overflows says False, and json_ready decides)."""
    if type(values) is not list:
        return False
    if values and type(values[0]) is list:
        if set(map(type, values)) != _LIST_TYPE:
            return False
        values = list(chain.from_iterable(values))
    return set(map(type, values)) <= _FLOAT_TYPE and math.isfinite(sum(values))


def _numpy_columns(table: PassTable) -> dict | None:
    """The table's numpy columns without :data:`ADDED_COLUMNS` (a smoothed table smoothed again),
    when it holds all of them with the canonical types (``time`` datetime64[ns], the key columns
    object arrays); else None (the DataFrame path)."""
    columns = table.numpy_columns()
    if columns is None or any(c not in columns for c in ("time", "station", "pass_id", "kind", "value", "sigma")):
        return None
    if columns["time"].dtype != np.dtype("datetime64[ns]") or any(
            columns[c].dtype != object for c in ("station", "pass_id", "kind")):
        return None
    return {name: values for name, values in columns.items() if name not in ADDED_COLUMNS}


def _without_added(frame):
    """``frame`` without :data:`ADDED_COLUMNS`, numbered 0..n-1 (the frame smooth fits)."""
    added = [c for c in ADDED_COLUMNS if c in frame.columns]
    if added:                    # (a drop of no columns still copies the frame)
        frame = frame.drop(columns=added)
    return frame.reset_index(drop=True)


def _with_added(frame, added_columns: dict):
    """The sample table's DataFrame: ``frame`` and the added columns in one concatenation (half the
    time of three insertions)."""
    import pandas as pd  # start-up: pandas only when a caller asks for the smoothed table's DataFrame

    return pd.concat([frame, pd.DataFrame(added_columns, index=frame.index)], axis=1)


def _column_table(frame, meta: dict, known: dict | None = None) -> PassTable:
    """``PassTable(frame, meta)`` holding :data:`_READ_COLUMNS` as numpy (``PassTable.column``'s
    own conversion of the frame, so the same arrays) and ``frame`` itself as its DataFrame.
    ``known``: columns already converted that way (the fit's own arrays), by name."""
    whole = PassTable(frame, meta)
    known = known or {}
    columns = {str(name): (known[str(name)] if str(name) in known else whole.column(str(name)))
               if str(name) in _READ_COLUMNS else None for name in frame.columns}
    return PassTable.from_columns(columns, meta, lambda: frame)


def _check_options(options: SmoothOptions) -> None:
    degree = options.degree
    if isinstance(degree, str):
        if degree != "auto":
            raise InputError("invalid option", column="--degree", found=degree, expected="an integer >= 0 or auto")
    elif int(degree) < 0:
        raise InputError("invalid option", column="--degree", found=degree, expected="an integer >= 0 or auto")
    if options.clip is not None and not (math.isfinite(options.clip) and options.clip >= 0):
        raise InputError("invalid option", column="--clip", found=options.clip, expected="K >= 0 (0: no rejection)")
    if options.clip is not None and 0 < options.clip < 1.5:
        raise InputError("invalid option", column="--clip", found=options.clip,
                         expected="K >= 1.5 (smaller K rejects good data), or 0 for no rejection")
    if options.grid_step_s is not None and not (math.isfinite(options.grid_step_s) and options.grid_step_s > 0):
        raise InputError("invalid option", column="--grid", found=options.grid_step_s, expected="a step > 0 (s)")
    if int(options.max_degree) < 0:
        raise InputError("invalid option", column="--max-degree", found=options.max_degree, expected="an integer >= 0")
    if not options.tca_max_gap_s > 0:
        raise InputError("invalid option", column="--tca-max-gap", found=options.tca_max_gap_s,
                         expected="a duration > 0 (s)")
    if options.basis not in ("chebyshev", "legendre"):
        raise InputError("invalid option", column="--basis", found=options.basis, expected="chebyshev or legendre")


def _check_sigma(sigma: np.ndarray, kind: np.ndarray, frame_of, kinds, source) -> None:
    """InputError when a sample of ``kinds`` has a sigma that is not finite and > 0; ``frame_of()``
    the fitted frame, built only to name the first such sample."""
    wrong = ~(np.isfinite(sigma) & (sigma > 0))
    if not wrong.any():          # (the kinds' rows are looked up only when some sigma is wrong)
        return
    bad = np.isin(kind, list(kinds)) & wrong
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        row = frame_of().iloc[i]
        raise InputError(f"sigma must be finite and > 0 ({int(bad.sum())} samples are not; first: "
                         f"{row['station']}/{row['pass_id']}/{row['kind']} at {row['time']})",
                         file=source, column="sigma", found=float(sigma[i]), expected="a 1-sigma > 0")


def _group_rows(frame, kinds, keys: dict | None = None) -> dict:
    """``{(station, pass_id, kind): row positions, increasing}`` of the rows of ``kinds`` (``frame``
    numbered 0..n-1): ``groupby([...]).indices`` of those rows, by the columns' codes when each
    holds a few ``str`` labels (:func:`_coded_groups`), else by one pass over the three columns
    as Python lists (a fifth of the groupby's time on a pass of two kinds); the groupby itself
    when a key is not a string (a missing one: the groupby leaves it out). ``keys``: the three
    columns' ``to_numpy()``, when the caller has them."""
    arrays = [frame[c].to_numpy() if keys is None else keys[c] for c in ("station", "pass_id", "kind")]
    coded = _coded_groups(arrays, kinds)
    if coded is not None:
        return coded
    keys = [values.tolist() for values in arrays]
    wanted = set(kinds)
    groups: dict = {}
    for i, key in enumerate(zip(*keys)):
        if key[2] in wanted:
            rows = groups.get(key)
            if rows is None:
                if not all(type(k) is str for k in key):
                    break
                rows = groups[key] = []
            rows.append(i)
    else:
        return {key: np.array(rows, dtype=np.intp) for key, rows in groups.items()}
    if callable(frame):          # the caller's frame, built only for this fallback
        frame = frame()
    selected = frame[frame["kind"].isin(list(kinds))]
    positions = selected.index.to_numpy()
    return {key: positions[idx] for key, idx in selected.groupby(["station", "pass_id", "kind"], sort=True)
            .indices.items()}


def _coded_groups(arrays: list, kinds) -> dict | None:
    """:func:`_group_rows` of key columns of a few ``str`` labels each (a pass file's: one station,
    one pass, two kinds; :func:`~trackproc.io.tables.few_labels`), by their codes in numpy: the
    rows of each (station, pass, kind) code in increasing order (a stable sort), the groups in
    order of first row as the row loop makes them. None when a column is not such labels."""
    from trackproc.io.tables import few_labels

    coded = [few_labels(values) for values in arrays]
    if any(c is None for c in coded):
        return None
    (station, stations), (pass_id, passes), (kind, kind_labels) = coded
    wanted = set(kinds)
    rows = np.flatnonzero(np.array([label in wanted for label in kind_labels])[kind])
    if not rows.size:
        return {}
    key = (station[rows] * len(passes) + pass_id[rows]) * len(kind_labels) + kind[rows]
    order = np.argsort(key, kind="stable")
    ordered = key[order]
    starts = np.flatnonzero(np.concatenate(([True], ordered[1:] != ordered[:-1])))
    groups = np.split(rows[order], starts[1:])
    groups.sort(key=lambda g: g[0])
    return {(stations[station[g[0]]], passes[pass_id[g[0]]], kind_labels[kind[g[0]]]): g.astype(np.intp, copy=False)
            for g in groups}


class _Columns:
    """The columns a fit reads, as numpy, of the whole (renumbered) frame: ``time_ns`` UTC
    nanoseconds, ``value``, ``sigma``; ``epoch(row)`` the row's time, UTC ``datetime64[ns]``."""

    def __init__(self, frame):
        import pandas as pd  # start-up: only a table held as a DataFrame comes here

        self.time = frame["time"]
        if isinstance(self.time.dtype, pd.DatetimeTZDtype):
            # the array's own conversion to naive UTC (a fifteenth of the time through the Series'
            # .dt accessor, twice; the same numbers)
            self.utc = self.time.array.tz_convert(None).to_numpy().astype("datetime64[ns]")
        else:
            self.utc = self.time.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy().astype("datetime64[ns]")
        self.time_ns = self.utc.astype(np.int64)
        self.value = frame["value"].to_numpy(dtype=float)
        self.sigma = frame["sigma"].to_numpy(dtype=float)
        self.float_values = frame["value"].dtype == np.float64 and frame["sigma"].dtype == np.float64

    @classmethod
    def of_numpy(cls, columns: dict) -> "_Columns":
        """From numpy columns as :meth:`PassTable.column` gives them (``time`` naive UTC)."""
        self = cls.__new__(cls)
        self.utc = columns["time"]
        self.time_ns = self.utc.astype(np.int64)
        self.value = np.asarray(columns["value"], dtype=float)
        self.sigma = np.asarray(columns["sigma"], dtype=float)
        self.float_values = columns["value"].dtype == np.float64 and columns["sigma"].dtype == np.float64
        return self

    def known(self) -> dict:
        """The columns as ``PassTable.column`` gives them (``time`` naive UTC; ``value`` and
        ``sigma`` when the frame holds them as float64, as ingest writes them)."""
        return {"time": self.utc, **({"value": self.value, "sigma": self.sigma} if self.float_values else {})}

    def epoch(self, row: int) -> np.datetime64:
        return self.utc[row]


def _fit_group(columns: _Columns, rows: np.ndarray, station, pass_id, kind, options: SmoothOptions,
               doppler_mode) -> PassFit:
    """Fit one group: ``rows`` its rows of ``columns`` (in table order; fitted in time order, stable)."""
    rows = rows[np.argsort(columns.time_ns[rows], kind="stable")]
    epoch = columns.epoch(int(rows[0]))
    t_s = (columns.time_ns[rows] - columns.time_ns[int(rows[0])]) * 1e-9
    out = PassFit(station=station, pass_id=pass_id, kind=kind, rows=rows, epoch_utc=epoch, t_s=t_s)
    y = columns.value[rows]
    if kind == "azimuth":       # fit the continuous angle; a pass through north jumps by 2 pi
        y = np.unwrap(y)
    sigma = columns.sigma[rows]
    try:
        fit = smooth_pass(t_s, y, sigma, options.degree, clip=options.clip, basis=options.basis,
                          max_degree=options.max_degree)
    except SmoothingError as exc:
        out.status, out.error, out.reason = "failed", str(exc), exc.reason
        return out
    out.fit = fit
    if kind in TCA_KINDS:
        try:
            ca = closest_approach(fit, kind, doppler_mode)
            gap, margin = _coverage(t_s[fit.used], ca.t_s)
            out.tca_gap_s = gap
            at = iso(at_offset(out.epoch_utc, ca.t_s))
            where = f"closest approach of the fit at {at} ({ca.t_s:.1f} s into the pass)"
            if gap > options.tca_max_gap_s:
                raise SmoothingError("tca_not_observed", f"{where} falls in a {gap:.1f} s data gap "
                                     f"(limit {options.tca_max_gap_s:g} s): not observed")
            if margin < options.tca_max_gap_s:
                raise SmoothingError("tca_not_observed", f"{where} is {margin:.1f} s from an end of the data "
                                     f"(need {options.tca_max_gap_s:g} s on each side): not observed")
            out.tca = ca
            out.tca_spread = tca_degree_spread(t_s, y, sigma, fit, kind, doppler_mode, t_star=ca.t_s)
            if tca_uncertain(fit, ca, out.tca_spread[0]):
                out.warnings.append("tca_uncertain")
                spread, width = out.tca_spread[0], degree_spread_width(fit.degree)
                why = (f"moves by {spread:.3g} s over degrees {max(0, fit.degree - width)}-{fit.degree + width}, "
                       f"{spread / ca.sigma_s:.1f} times its sigma of {ca.sigma_s:.3g} s"
                       if math.isfinite(spread) and spread > TCA_SPREAD_RATIO * ca.sigma_s else
                       "has a sigma that assumes white noise, and the residuals are correlated (curve_unresolved)")
                out.tca_error = (f"{where} {why}: uncertain (uncertainty_s "
                                 f"{math.hypot(ca.sigma_s, spread) if math.isfinite(spread) else ca.sigma_s:.3g} s)")
        except SmoothingError as exc:
            out.tca_error = str(exc)
            out.warnings.append("tca_not_observed")
    span = fit.domain_s[1] - fit.domain_s[0]
    tu = t_s[fit.used]
    largest = float(np.max(np.diff(tu))) if tu.size > 1 else span
    if span > 0 and largest > LARGEST_GAP_FRACTION * span:
        out.warnings.append("largest_gap")
    if fit.rejection_capped:
        out.warnings.append("many_rejected")
    if fit.noise.unresolved:
        out.warnings.append("curve_unresolved")
    if not fit.clip_converged:
        out.warnings.append("clip_not_converged")
    out.status = "suspect" if out.warnings else "ok"
    return out


def _coverage(t_used: np.ndarray, t_star: float) -> tuple[float, float]:
    """(length of the data gap containing t*, shortest data span on either side of t*), seconds."""
    before = t_used[t_used <= t_star]
    after = t_used[t_used >= t_star]
    if before.size == 0 or after.size == 0:
        return math.inf, 0.0
    return float(after[0] - before[-1]), float(min(t_star - before[0], after[-1] - t_star))
