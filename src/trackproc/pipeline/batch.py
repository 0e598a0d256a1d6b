"""``trackproc batch``: many passes through a chain of steps, in parallel, resumable, cron-grade.

The chain is a list of named steps (:data:`CHAIN`: ingest, smooth, refine, estimate). Each step
is a small adapter (:class:`Step`) around one pipeline function:

- ``scope="input"`` steps run once per input file, in order, on an :class:`InputContext`
  (``ctx.table`` is the pass table handed from step to step; a step adds its side outputs and
  its key numbers). When the chain does not start with ``ingest`` the inputs are read as
  canonical pass files. ``ingest`` and ``smooth`` make the table (``Step.table``); ``refine``
  only reads it (the stale state refined from the input's pass, ``<name>.refined.json``; the
  pass with the most samples when an input holds several, :func:`refine_pass`).
- ``scope="window"`` steps run once per window of processed inputs (``estimate``: one orbit
  from all the passes of a window, ``[estimate] window_s``) on a :class:`WindowContext`.

Adding a step is an adapter and one :func:`register` call (see :func:`_refine`)::

    def _refine(ctx: InputContext, opt: dict) -> None:
        ...
        result = refine(table, initial, stations, RefineOptions(cost=opt["cost"], ...), orientation,
                        source=ctx.source)
        ctx.outputs[".refined.json"] = state_json(state, ...).encode("utf-8")
        ctx.numbers.update(converged=..., iterations=..., ...)

    register(Step("refine", "input", _refine, files=("refine.initial", "refine.eop", "ingest.stations"),
                  table=False))

plus its settings section in :mod:`trackproc.pipeline.batch_config` (the schema gives the
TOML keys, the flags and the environment variables). The position in :data:`CHAIN` fixes
where it runs.

Work and results (``OUTPUT`` is the output directory):

- ``OUTPUT/passes/<name>.parquet`` (the last table of the chain), the side outputs of each step
  (``<name>.smooth.json``, ``<name>.refined.json``), and ``<name>.batch.json``: the manifest —
  the content key, the status, the key numbers, the error and the outputs with their sizes and
  SHA-256. ``<name>``
  is the input's path relative to its directory (or to the fixed part of its glob), without
  the suffix, so sub-directories are mirrored.
- ``OUTPUT/estimates/<window>.json`` (state file), ``<window>.residuals.parquet``, manifest.
- ``OUTPUT/summary.json`` and ``OUTPUT/summary.csv``: one record per input and per window.

The content key of a result is the SHA-256 of the input's bytes, the settings of the steps that
produced it (the content of every file they name: stations table, initial state, EOP file) and
the trackproc version, in two stages: the table key (input, table steps) and, when the chain
has side steps (refine), the key over the table key and their settings. A window's key covers
its members' table keys (it reads their pass tables). A result whose manifest holds the same
key and whose outputs are all present is up to date and skipped (``force`` redoes it); one
whose table key alone matches runs only its side steps, on its stored pass table, and keeps its
table outputs untouched (so changing a ``[refine]`` setting redoes the refinements and nothing
else). A failure caused by the data (an :class:`~trackproc.errors.TrackprocError`) is recorded
the same way and not retried until its input or the settings change (or ``retry_failed``); an
unexpected failure (a bug, a worker that died, a full disk) is never recorded, so the next run
retries it.

Every file goes through :mod:`trackproc.io.atomic`; a manifest is written after its outputs,
so an interrupted run leaves complete results and redoes only the rest. A lock
(``OUTPUT/.batch.lock``, ``fcntl.flock``) keeps two runs on the same output directory apart.

Workers: in this process (``workers=1``), a process pool (``workers=N``, 0 = one per core), or a
Dask distributed cluster (``scheduler``; the workers need trackproc installed and, for the
EOP file and DopTrack sidecars, the same file system). Every task is a pure function of its
payload (input bytes, settings, file contents), and the driver alone writes files, so every
way of running gives the same bytes.

Exit status (:attr:`BatchResult.exit_code`): 0 every input and window ok, 3 some failed, 1 all
failed; usage errors raise :class:`~trackproc.errors.InputError` (2) before any work.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import glob
import hashlib
import io
import json
import logging
import math
import os
import socket
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

from trackproc import __version__
from trackproc.errors import (EXIT_OK, EXIT_PARTIAL, EXIT_PROCESSING, InputError, ProcessingError,
                              TrackprocError)
from trackproc.io.atomic import write_bytes, write_text
from trackproc.io.jsonutil import dumps, json_ready
from trackproc.pipeline.batch_config import Settings

log = logging.getLogger("trackproc.batch")

#: The canonical order of the chain; a configured chain is a subsequence of it.
CHAIN = ("ingest", "smooth", "refine", "estimate")
PASSES_DIR = "passes"
ESTIMATES_DIR = "estimates"
LOCK_NAME = ".batch.lock"
MANIFEST_SUFFIX = ".batch.json"
SUMMARY_JSON = "summary.json"
SUMMARY_CSV = "summary.csv"
#: Columns of summary.csv, one row per input ("pass") and per window ("estimate").
CSV_COLUMNS = ("task", "input", "status", "skipped", "samples", "passes", "stations", "start_utc", "end_utc",
               "fits_ok", "fits_suspect", "fits_failed", "kind", "rms", "rms_unit", "tca_utc", "tca_sigma_s",
               "fca_hz", "refined_pass", "traverse_utc", "converged", "iterations", "wrms", "residual_rms",
               "residual_rms_unit", "sigma_radial_m", "sigma_along_m", "sigma_cross_m", "output", "error")
#: Kinds in the order their fit is reported as the input's key numbers.
_PRIMARY_KINDS = ("doppler", "range_rate", "range", "elevation", "azimuth")


# ============================================================================= the chain

@dataclass
class InputContext:
    """What an input step reads and writes.

    ``name`` (result name), ``source`` (the input's path, as errors and metadata name it),
    ``data`` (its bytes), ``files`` (``"section.key"`` -> bytes of the files the settings name),
    ``paths`` (``"section.key"`` -> path), ``table`` (the :class:`~trackproc.io.passfile.PassTable`
    handed from step to step), ``outputs`` (suffix -> bytes, e.g. ``".smooth.json"``),
    ``numbers`` (key numbers for the summary), ``details`` (larger per-step records for
    summary.json), ``warnings``.
    """

    name: str
    source: str
    data: bytes
    files: dict
    paths: dict
    table: object = None
    outputs: dict = field(default_factory=dict)
    numbers: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


@dataclass
class WindowContext:
    """What a window step reads and writes: ``members`` is a list of (source name, pass-file
    bytes) of the window's processed inputs, in name order; the rest as :class:`InputContext`."""

    name: str
    members: list
    files: dict
    paths: dict
    outputs: dict = field(default_factory=dict)
    numbers: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


@dataclass(frozen=True)
class Step:
    """A named step: ``scope`` "input" or "window", ``run(ctx, options)`` with ``options`` the
    step's settings section, ``files``: settings (``"section.key"``) naming files whose content
    the step reads (hashed into the content key and shipped to the workers). ``table``: the step
    makes the pass table (ingest, smooth); False for an input step that only reads it and adds
    side outputs and numbers (refine): such steps run after the table steps, and changing only
    their settings redoes only them, from the stored pass table."""

    name: str
    scope: str
    run: Callable
    files: tuple = ()
    table: bool = True


STEPS: dict[str, Step] = {}


def register(step: Step) -> Step:
    """Make ``step`` available to chains (its name must be in :data:`CHAIN`)."""
    if step.name not in CHAIN:
        raise ValueError(f"step {step.name!r} has no place in CHAIN {CHAIN}")
    if step.scope not in ("input", "window"):
        raise ValueError(f"step scope must be 'input' or 'window', not {step.scope!r}")
    STEPS[step.name] = step
    return step


def _read_input(data: bytes, source: str, opt: dict):
    """Raw samples of one input file's bytes (the dispatch of :func:`trackproc.io.tabular.read_raw`,
    on bytes already read: the driver hashed exactly these)."""
    from trackproc.io import tabular

    if not data.strip():
        raise InputError("empty input", file=source, row=1, found="no data",
                         expected="a CSV, Parquet, Arrow IPC, DopTrack, Orekit .aer or CCSDS TDM file")
    layout = opt["layout"]
    if layout == "auto":
        layout = tabular.detect_layout(data, Path(source).name)
    if layout == "doptrack":
        from trackproc.io.doptrack import read_doptrack

        return read_doptrack(data, source, data_path=Path(source), carrier_hz=opt["carrier_hz"],
                             drop_invalid=opt["drop_invalid"])
    if layout == "aer":
        from trackproc.io.orekit_aer import read_aer

        return read_aer(data, source, drop_invalid=opt["drop_invalid"])
    if layout == "tdm":
        from trackproc.io.tdm import read_tdm

        return read_tdm(data, source, carrier_hz=opt["carrier_hz"], two_way_range=opt["tdm_two_way_range"])
    table = tabular.source_table(data, source)
    if layout == "long" or (layout in ("auto", "table") and tabular.is_long_layout(table)):
        return tabular.read_long(table, drop_invalid=opt["drop_invalid"])
    return tabular.read_wide(table, drop_invalid=opt["drop_invalid"])


def _ingest(ctx: InputContext, opt: dict) -> None:
    """ingest: the input file -> the canonical pass table (:func:`trackproc.pipeline.ingest.ingest`)."""
    from trackproc.io.stations import parse_stations
    from trackproc.pipeline.ingest import IngestOptions, ingest

    stations = ({} if ctx.files.get("ingest.stations") is None
                else parse_stations(ctx.files["ingest.stations"], ctx.paths["ingest.stations"]))
    raw = _read_input(ctx.data, ctx.source, opt)
    result = ingest([raw], stations, IngestOptions(
        carrier_hz=opt["carrier_hz"], doppler_mode=opt["mode"], max_gap_s=opt["max_gap_s"],
        drop_invalid=opt["drop_invalid"], sigma_range_m=opt["sigma_range_m"],
        sigma_range_rate_m_s=opt["sigma_range_rate_m_s"], sigma_doppler_hz=opt["sigma_doppler_hz"],
        sigma_angle_deg=opt["sigma_angle_deg"]))
    ctx.table = result.table
    ctx.warnings.extend(result.warnings)
    dropped = sum(result.dropped.values())
    if dropped:
        ctx.warnings.append("dropped %d invalid samples: %s" % (
            dropped, ", ".join(f"{reason} {n}" for reason, n in result.dropped.items())))
    ctx.numbers["dropped"] = dropped


def _smooth(ctx: InputContext, opt: dict) -> None:
    """smooth: polynomial fit of every pass and kind (:func:`trackproc.pipeline.smooth.smooth`)."""
    from trackproc.pipeline.smooth import SmoothOptions, smooth, summary_json

    result = smooth(ctx.table, SmoothOptions(
        degree=opt["degree"], clip=opt["clip"] if opt["clip"] > 0 else None, kinds=list(opt["kinds"]) or None,
        basis=opt["basis"], max_degree=opt["max_degree"], tca_max_gap_s=opt["tca_max_gap_s"]),
        source=ctx.source)
    ctx.table = result.table
    ctx.outputs[".smooth.json"] = summary_json(result.summary).encode("utf-8")
    counts = result.summary["counts"]
    ctx.numbers.update(fits_ok=counts["ok"], fits_suspect=counts["suspect"], fits_failed=counts["failed"])
    records = result.summary["fits"]
    ctx.details["fits"] = [_fit_numbers(rec) for rec in records]
    fitted = [rec for rec in records if rec["status"] != "failed"]
    fitted.sort(key=lambda r: (_PRIMARY_KINDS.index(r["kind"]) if r["kind"] in _PRIMARY_KINDS else 99,
                               r["tca"]["status"] != "ok" if "tca" in r else True, r["station"], r["pass_id"]))
    if fitted:
        ctx.numbers.update({k: v for k, v in _fit_numbers(fitted[0]).items()
                            if k in ("kind", "rms", "rms_unit", "tca_utc", "tca_sigma_s", "fca_hz")})
    for f in result.fits:
        if f.status == "failed":
            ctx.warnings.append(f"{f.label}: failed: {f.error}")
        elif f.status == "suspect":
            ctx.warnings.append(f"{f.label}: suspect ({', '.join(f.warnings)})")


def _fit_numbers(rec: dict) -> dict:
    tca = rec.get("tca") or {}
    return {"station": rec["station"], "pass_id": rec["pass_id"], "kind": rec["kind"], "status": rec["status"],
            "n_samples": rec["n_samples"], "n_used": rec.get("n_used"), "degree": rec.get("degree"),
            "rms": rec.get("rms"), "rms_unit": rec.get("unit"),
            "tca_utc": tca.get("time_utc"), "tca_sigma_s": tca.get("sigma_s"), "fca_hz": rec.get("fca_hz"),
            "error": rec.get("error") or tca.get("error")}


def _estimate(ctx: WindowContext, opt: dict) -> None:
    """estimate: one orbit and its biases from every pass of the window
    (:func:`trackproc.pipeline.estimate.estimate`)."""
    import numpy as np

    from trackproc.io.eop import earth_orientation
    from trackproc.io.passfile import PassTable, parse_pass_table
    from trackproc.io.residuals import residuals_bytes
    from trackproc.io.stations import parse_stations
    from trackproc.io.statefile import format_epoch, parse_epoch, parse_state, state_json
    from trackproc.pipeline.estimate import EstimateOptions, estimate

    orientation, warning = earth_orientation(opt["eop"], opt["dut1"])
    if warning:
        ctx.warnings.append(warning)
    tables = []
    for source, data in ctx.members:
        table = parse_pass_table(data, source)
        frame = table.frame
        if opt["drop_flagged"] and "flag" in frame.columns:
            frame = frame[~frame["flag"].astype(bool)].reset_index(drop=True)
        if len(frame):
            tables.append((source, PassTable(frame, table.meta)))
    if not tables:
        raise ProcessingError("no samples left in the window (all flagged by the smoother)")
    initial_bytes, initial_path = ctx.files["estimate.initial"], ctx.paths["estimate.initial"]
    if initial_bytes.lstrip()[:1] == b"{":
        state0 = parse_state(initial_bytes, initial_path, orientation)
    else:
        from trackproc.io.tle import parse_tle, tle_state

        epoch = opt["epoch"]
        at = None
        if epoch is not None and epoch.lower() == "first":
            at = min(t.frame["time"].min() for _, t in tables).tz_convert("UTC").tz_localize(None).to_datetime64()
        elif epoch is not None and epoch.lower() != "initial":
            at = parse_epoch(epoch, column="estimate.epoch")
        state0 = tle_state(parse_tle(initial_bytes.decode("utf-8", errors="replace"), initial_path), at=at,
                           eop=orientation)
    stations = (None if ctx.files.get("ingest.stations") is None
                else parse_stations(ctx.files["ingest.stations"], ctx.paths["ingest.stations"]))
    options = EstimateOptions(
        range_bias=opt["range_bias"], doppler_bias=opt["doppler_bias"], doppler_bias_per=opt["doppler_bias_per"],
        angle_bias=opt["angle_bias"], apriori_sigma=dict(opt["apriori_sigma"]), force=opt["force"],
        earth=opt["earth"], range_rate_model=opt["range_rate_model"], max_iterations=opt["max_iterations"],
        clip=opt["clip"] if opt["clip"] > 0 else None, epoch=opt["epoch"], kinds=list(opt["kinds"]) or None)
    result = estimate(tables, state0, stations, options, orientation)
    state = result.state
    ctx.outputs[".json"] = state_json(state, force=opt["force"], eop_source=orientation.source).encode("utf-8")
    meta = {"epoch": format_epoch(state.epoch), "parameters": result.solution.names, "force_model": opt["force"],
            "range_rate_model": result.problem.range_rate_model, "sources": [s for s, _ in tables]}
    ctx.outputs[".residuals.parquet"] = residuals_bytes(result.residuals, meta)
    diag = state.diagnostics
    sig = diag.get("sigma_rtn") or {}
    ctx.numbers.update(
        samples=int(diag["measurements"]), passes=int(sum(t.frame["pass_id"].nunique() for _, t in tables)),
        converged=bool(diag["converged"]), iterations=int(diag["iterations"]), wrms=diag.get("wrms"),
        variance_factor=diag.get("variance_factor"), edited=int(diag.get("edited", 0)),
        epoch_utc=format_epoch(state.epoch), sigma_radial_m=sig.get("radial_m"), sigma_along_m=sig.get("along_m"),
        sigma_cross_m=sig.get("cross_m"))
    ctx.details["parameters"] = {n: {"value": float(v), "sigma": float(s)}
                                 for n, v, s in zip(result.solution.names, np.asarray(result.solution.values),
                                                    np.asarray(result.solution.sigma))}
    ctx.warnings.extend(result.warnings)


def _initial_state(data: bytes, path: str, orientation):
    """The stale state of ``refine.initial``: a JSON state file, or a TLE (at its epoch here; refine
    evaluates it by SGP4 at the traverse epoch)."""
    from trackproc.io.statefile import parse_state

    if data.lstrip()[:1] == b"{":
        return parse_state(data, path, orientation)
    from trackproc.io.tle import parse_tle, tle_state

    return tle_state(parse_tle(data.decode("utf-8", errors="replace"), path), eop=orientation)


#: The rule that picks the pass refine uses when an input holds several (docs/batch.md).
REFINE_PASS_RULE = "the pass with the most samples of the kind refine uses (ties: the earliest)"


def refine_pass(table) -> tuple:
    """``(table, chosen, candidates)``: the one pass (station, pass id) refine uses of an input, by
    :data:`REFINE_PASS_RULE`, with all its samples; ``candidates``: every pass of that kind as
    ``{"station", "pass_id", "samples", "start_utc"}``, the chosen first. An input of one pass (or
    without Doppler or range-rate: refine reports that) is returned as it is."""
    from trackproc.io.passfile import PassTable
    from trackproc.pipeline.refine import RANGE_RATE_KINDS

    frame = table.frame
    kinds = set(frame["kind"].astype(str))
    kind = next((k for k in RANGE_RATE_KINDS if k in kinds), None)
    if kind is None:
        return table, None, []
    sub = frame[frame["kind"].astype(str) == kind]
    groups = sub.groupby([sub["station"].astype(str), sub["pass_id"].astype(str)], sort=True)["time"]
    counts, starts = groups.size(), groups.min()
    order = sorted(counts.index, key=lambda k: (-int(counts[k]), starts[k], k))
    candidates = [{"station": st, "pass_id": pid, "samples": int(counts[(st, pid)]),
                   "start_utc": starts[(st, pid)].tz_convert("UTC").strftime("%Y-%m-%dT%H:%M:%S.%fZ")}
                  for st, pid in order]
    station, pass_id = order[0]
    if len(order) == 1:
        return table, order[0], candidates
    keep = (frame["station"].astype(str) == station) & (frame["pass_id"].astype(str) == pass_id)
    return PassTable(frame[keep].reset_index(drop=True), dict(table.meta or {})), order[0], candidates


def _refine(ctx: InputContext, opt: dict) -> None:
    """refine: the stale state refined from the input's pass at its traverse point
    (:func:`trackproc.pipeline.refine.refine`, as ``trackproc refine PASS --pass-id ID``); the pass
    with the most samples when the input holds several (:func:`refine_pass`)."""
    from trackproc.io.eop import earth_orientation
    from trackproc.io.stations import parse_stations
    from trackproc.io.statefile import state_json
    from trackproc.pipeline.refine import RefineOptions, refine

    orientation, warning = earth_orientation(opt["eop"], opt["dut1"])
    if warning:
        ctx.warnings.append(warning)
    initial = _initial_state(ctx.files["refine.initial"], ctx.paths["refine.initial"], orientation)
    stations = (None if ctx.files.get("ingest.stations") is None
                else parse_stations(ctx.files["ingest.stations"], ctx.paths["ingest.stations"]))
    table, chosen, candidates = refine_pass(ctx.table)
    if len(candidates) > 1:
        ctx.warnings.append("%d passes in the input: refined %s/%s (%d samples: %s); not refined: %s" % (
            len(candidates), chosen[0], chosen[1], candidates[0]["samples"], REFINE_PASS_RULE,
            ", ".join(f"{c['station']}/{c['pass_id']} ({c['samples']})" for c in candidates[1:])))
    options = RefineOptions(
        cost=opt["cost"], circular=opt["circular"], circular_tolerance=opt["circular_tolerance"],
        doppler_bias=None if opt["doppler_bias"] == "auto" else opt["doppler_bias"], apriori=opt["apriori"],
        apriori_sigma=dict(opt["apriori_sigma"]), force=opt["force"], earth=opt["earth"],
        range_rate_model=opt["range_rate_model"], max_iterations=opt["max_iterations"],
        clip=opt["clip"] if opt["clip"] > 0 else None, reweight=opt["reweight"])
    try:
        result = refine(table, initial, stations, options, orientation, source=ctx.source)
    except ProcessingError as exc:  # no convergence, too few samples, ...: say which step and pass
        where = f" {chosen[0]}/{chosen[1]}" if chosen else ""
        raise ProcessingError(f"refine{where}: {exc}", exc.diagnostics) from None
    state = result.state if opt["output_epoch"] == "traverse" else result.stale_epoch_state
    ctx.outputs[".refined.json"] = state_json(state, force=opt["force"], eop_source=orientation.source).encode("utf-8")
    diag = result.state.diagnostics
    method = result.state.extra["refinement"]
    sig = diag["sigma_rtn"]
    rms = diag["residual_rms"]
    ctx.numbers.update(
        refined_pass=f"{method['station']}/{method['pass_id']}", traverse_utc=diag["traverse"]["epoch"],
        converged=bool(diag["converged"]), iterations=int(diag["iterations"]), residual_rms=rms["value"],
        residual_rms_unit=rms["unit"], sigma_radial_m=sig["radial_m"], sigma_along_m=sig["along_m"],
        sigma_cross_m=sig["cross_m"])
    ctx.details["refine"] = {
        "station": method["station"], "pass_id": method["pass_id"], "kind": method["kind"],
        "rule": REFINE_PASS_RULE, "candidates": candidates, "cost": method["cost"], "circular": method["circular"],
        "apriori": method["apriori"], "message": diag["message"], "samples": diag["samples"], "edited": diag["edited"],
        "variance_factor": diag["variance_factor"], "residual_rms": rms, "max_elevation_deg": diag["max_elevation_deg"],
        "traverse": diag["traverse"], "sigma_rtn": sig, "output_epoch": opt["output_epoch"],
        "unobservable": diag["observability"].get("unobservable"),
        "parameters": {n: {"value": float(v), "sigma": float(e)}
                       for n, v, e in zip(result.state.parameters, result.state.values, result.state.sigma)}}
    ctx.warnings.extend(result.warnings)


register(Step("ingest", "input", _ingest, files=("ingest.stations",)))
register(Step("smooth", "input", _smooth))
register(Step("refine", "input", _refine, files=("refine.initial", "refine.eop", "ingest.stations"), table=False))
register(Step("estimate", "window", _estimate, files=("estimate.initial", "estimate.eop", "ingest.stations")))


@dataclass(frozen=True)
class Chain:
    """The configured chain: input steps, then window steps (names, in :data:`CHAIN` order)."""

    input_steps: tuple
    window_steps: tuple

    @property
    def names(self) -> tuple:
        return self.input_steps + self.window_steps

    @property
    def table_steps(self) -> tuple:
        """The input steps that make the pass table (``passes/<name>.parquet``)."""
        return tuple(n for n in self.input_steps if STEPS[n].table)

    @property
    def side_steps(self) -> tuple:
        """The input steps after them that only read the table (their own content key stage)."""
        return tuple(n for n in self.input_steps if not STEPS[n].table)

    @property
    def reads_raw(self) -> bool:
        """True when the inputs are raw files for ``ingest``; else canonical pass files."""
        return bool(self.input_steps) and self.input_steps[0] == "ingest"

    def files(self, scope: str) -> tuple:
        """Settings naming files the steps of ``scope`` read: "input", "window", or the two stages
        of the input steps, "table" and "side"."""
        names = {"input": self.input_steps, "window": self.window_steps, "table": self.table_steps,
                 "side": self.side_steps}[scope]
        return tuple(sorted({f for n in names for f in STEPS[n].files}))


def make_chain(names: Sequence[str]) -> Chain:
    """Validate a configured chain (names known, in order, none twice)."""
    names = [str(n).strip().lower() for n in names if str(n).strip()]
    if not names:
        raise InputError("no steps", column="batch.steps", expected="a subsequence of " + ", ".join(CHAIN))
    for name in names:
        if name not in CHAIN:
            raise InputError("unknown step", column="batch.steps", found=name,
                             expected="steps among " + ", ".join(CHAIN))
    if len(set(names)) != len(names) or names != sorted(names, key=CHAIN.index):
        raise InputError("steps out of order or repeated", column="batch.steps", found=", ".join(names),
                         expected="each step at most once, in the order " + " -> ".join(CHAIN))
    input_steps = tuple(n for n in names if STEPS[n].scope == "input")
    window_steps = tuple(n for n in names if STEPS[n].scope == "window")
    tables = [STEPS[n].table for n in input_steps]
    if tables != sorted(tables, reverse=True):  # the registry's promise, not the user's error
        raise ValueError(f"input steps that only read the pass table must follow those that make it: {input_steps}")
    return Chain(input_steps, window_steps)


# ============================================================================= tasks (run in workers)

@dataclass
class Task:
    """One unit of work, self-contained so that it can run in any process (pickled to workers).

    ``kind``: "input" or "window"; ``data``: the input's bytes (input) or ``members`` (window);
    ``options``: section -> settings of the steps; ``files``/``paths``: see :class:`InputContext`.
    Input tasks run ``steps`` (the table stage), then ``side_steps`` (the steps that only read
    the table, :attr:`Chain.side_steps`); with ``stage`` (the stored table stage of an earlier
    run: numbers, details, warnings, outputs) ``data`` is that run's pass table, ``steps`` is
    empty and only the side steps run. ``table_key``: the content key of the table stage.
    """

    kind: str
    name: str
    key: str
    steps: tuple
    options: dict
    files: dict
    paths: dict
    source: str = ""
    data: bytes = b""
    members: list = field(default_factory=list)
    reads_raw: bool = True
    side_steps: tuple = ()
    stage: Optional[dict] = None
    table_key: str = ""


@dataclass
class TaskResult:
    """What a task returns: status ``ok`` or ``failed``; ``error_type`` input | processing (data
    errors, recorded) | internal (never recorded, retried next run); outputs suffix -> bytes;
    ``stage``: the table stage (numbers, details, warnings, output suffixes) of an input task with
    side steps; ``reused``: that stage was the stored one (only the side steps ran)."""

    kind: str
    name: str
    key: str
    status: str
    numbers: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    outputs: dict = field(default_factory=dict)
    error: Optional[str] = None
    error_type: Optional[str] = None
    trace: Optional[str] = None
    seconds: float = 0.0
    stage: Optional[dict] = None
    reused: bool = False
    table_key: str = ""


_task_log = threading.local()


class _TaskLogFilter(logging.Filter):
    """While a task runs in this thread, what the pipeline logs on the ``trackproc`` logger
    (warnings: e.g. an ignored column) becomes the task's warnings instead of reaching any
    handler, so the same warnings are reported whichever process ran the task (thread-safe:
    Dask workers may run several tasks in threads)."""

    def filter(self, record):
        sink = getattr(_task_log, "sink", None)
        if sink is None:
            return True
        if record.levelno >= logging.WARNING:
            sink.append(record.getMessage())
        return False


_TASK_LOG_FILTER = _TaskLogFilter()


def run_task(task: Task) -> TaskResult:
    """Run one task; every exception becomes a failed :class:`TaskResult` (never raises)."""
    t0 = time.perf_counter()
    ctx = None
    logger = logging.getLogger("trackproc")
    if _TASK_LOG_FILTER not in logger.filters:
        logger.addFilter(_TASK_LOG_FILTER)
    level = logger.level
    if logger.getEffectiveLevel() > logging.WARNING:  # --quiet, in this process: still collect warnings
        logger.setLevel(logging.WARNING)
    messages: list = []
    _task_log.sink = messages
    stage = None
    try:
        if task.kind == "input":
            ctx = InputContext(task.name, task.source, task.data, task.files, task.paths)
            if not task.reads_raw:
                from trackproc.io.passfile import parse_pass_table

                ctx.table = parse_pass_table(task.data, task.source)
            if task.stage is not None:  # the table stage is stored: only the side steps run
                stage = task.stage
                ctx.numbers = dict(stage["numbers"])
                ctx.details = dict(stage["details"])
                ctx.warnings = list(stage["warnings"])
            else:
                for name in task.steps:
                    STEPS[name].run(ctx, task.options[name])
                from trackproc.io.passfile import pass_table_bytes

                ctx.outputs[".parquet"] = pass_table_bytes(ctx.table, "parquet")
                ctx.numbers = {**_table_numbers(ctx.table), **ctx.numbers}
                if task.side_steps:
                    ctx.warnings.extend(messages)  # in the order a run from the stored stage gives
                    messages.clear()
                    stage = {"numbers": json_ready(ctx.numbers), "details": json_ready(ctx.details),
                             "warnings": list(ctx.warnings), "outputs": sorted(ctx.outputs)}
            for name in task.side_steps:
                STEPS[name].run(ctx, task.options[name])
        else:
            ctx = WindowContext(task.name, task.members, task.files, task.paths)
            ctx.numbers["inputs"] = len(task.members)
            for name in task.steps:
                STEPS[name].run(ctx, task.options[name])
        status, error, error_type, trace = "ok", None, None, None
    except TrackprocError as exc:
        status, error, trace = "failed", str(exc), None
        error_type = "input" if isinstance(exc, InputError) else "processing"
    except Exception as exc:  # noqa: BLE001 - a bug or the machine: reported, never stops the batch
        status, error, error_type = "failed", f"internal error: {type(exc).__name__}: {exc}", "internal"
        trace = traceback.format_exc()
    finally:
        _task_log.sink = None
        if logger.level != level:
            logger.setLevel(level)
    ok = status == "ok"
    return TaskResult(kind=task.kind, name=task.name, key=task.key, status=status,
                      numbers=json_ready(ctx.numbers) if ok else {}, details=json_ready(ctx.details) if ok else {},
                      warnings=(list(ctx.warnings) if ctx is not None else []) + messages,
                      outputs=ctx.outputs if ok else {}, error=error, error_type=error_type, trace=trace,
                      seconds=time.perf_counter() - t0, stage=stage if ok else None,
                      reused=task.stage is not None, table_key=task.table_key)


def _table_numbers(table) -> dict:
    frame = table.frame
    times = frame["time"]
    iso = lambda t: t.tz_convert("UTC").strftime("%Y-%m-%dT%H:%M:%S.%fZ")  # noqa: E731
    return {"samples": int(len(frame)), "passes": int(frame[["station", "pass_id"]].drop_duplicates().shape[0]),
            "stations": " ".join(sorted(frame["station"].astype(str).unique())),
            "kinds": " ".join(sorted(frame["kind"].astype(str).unique())),
            "start_utc": iso(times.min()) if len(frame) else None, "end_utc": iso(times.max()) if len(frame) else None}


# ============================================================================= executors

#: Thread-count variables of the BLAS/OpenMP libraries numpy and scipy may use.
BLAS_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
                         "NUMEXPR_NUM_THREADS")


def single_thread_blas() -> None:
    """One BLAS/OpenMP thread in this process (takes effect when set before numpy is imported).

    A batch runs its inputs in parallel, one per worker; threads inside the small matrix
    operations of one pass only contend for the same cores (ingest + smooth ran 4.4 times slower
    with OpenBLAS's default threads on a busy 2-core machine), and a threaded reduction may
    change the last bits of a sum. Worker processes always start with this; Dask's workers
    already do the same (``distributed.nanny.pre-spawn-environ``).
    """
    for name in BLAS_THREAD_VARIABLES:
        os.environ[name] = "1"


class _SerialExecutor:
    """Runs each task in this process when it is submitted."""

    label = "this process (--workers 1)"
    slots = 1

    def submit(self, task: Task):
        from concurrent.futures import Future

        future: Future = Future()
        future.set_result(run_task(task))
        return future

    @staticmethod
    def wait_first(futures):
        return set(futures), set()

    def close(self):
        pass


class _PoolExecutor:
    """A process pool (forkserver start: no fork of this process's threads)."""

    def __init__(self, workers: int):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        context = multiprocessing.get_context(method)
        if method == "forkserver":
            context.set_forkserver_preload(["trackproc.pipeline.batch"])
        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=single_thread_blas)
        self.label = f"{workers} worker processes"
        self.slots = 2 * workers

    def submit(self, task: Task):
        return self.pool.submit(run_task, task)

    @staticmethod
    def wait_first(futures):
        from concurrent.futures import FIRST_COMPLETED, wait

        done, pending = wait(futures, return_when=FIRST_COMPLETED)
        return done, pending

    def close(self):
        self.pool.shutdown(wait=True, cancel_futures=True)


class _DaskExecutor:
    """An existing Dask distributed cluster (``tcp://host:port``)."""

    def __init__(self, address: str):
        try:
            from distributed import Client
        except ImportError:
            raise InputError("--scheduler needs Dask distributed, which is not installed", column="--scheduler",
                             found=address, expected="pip install 'trackproc[dask]' (or dask[distributed]), "
                                                     "or run without --scheduler") from None
        try:
            self.client = Client(address, timeout="20s", set_as_default=False)
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError (bad address) ...
            raise ProcessingError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        threads = sum(self.client.nthreads().values()) or 1
        self.label = f"Dask scheduler {address} ({len(self.client.nthreads())} workers, {threads} threads)"
        self.slots = 2 * threads

    def submit(self, task: Task):
        import uuid

        return self.client.submit(run_task, task, pure=False,
                                  key=f"trackproc-batch-{task.kind}-{task.key[:12]}-{uuid.uuid4().hex[:8]}")

    def wait_first(self, futures):
        from distributed import wait

        with self.client.as_current():
            result = wait(list(futures), return_when="FIRST_COMPLETED")
        return set(result.done), set(result.not_done)

    def close(self):
        with contextlib.suppress(Exception):
            self.client.close()


def _outcome(future, task: Task) -> TaskResult:
    """The task's result, or a failed result when the machinery failed (worker died, ...)."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001
        return TaskResult(kind=task.kind, name=task.name, key=task.key, status="failed",
                          error=f"internal error: {type(exc).__name__}: {exc}", error_type="internal",
                          trace=traceback.format_exc())


def _is_broken_pool(result: TaskResult) -> bool:
    return result.error_type == "internal" and "BrokenProcessPool" in (result.error or "")


def _run_isolated(task: Task) -> TaskResult:
    """Run one task in a fresh one-process pool (after a worker died: find the culprit)."""
    pool = _PoolExecutor(1)
    try:
        return _outcome(pool.submit(task), task)
    finally:
        pool.close()


def _execute(executor, tasks: Sequence, make_task: Callable, on_result: Callable) -> None:
    """Submit ``make_task(item)`` for each item with at most ``executor.slots`` in flight (so that
    input bytes are read only shortly before they are needed); ``on_result(item, result)``."""
    pending: dict = {}
    broken: list = []
    queue = list(tasks)
    queue.reverse()
    while queue or pending:
        while queue and len(pending) < executor.slots:
            item = queue.pop()
            task = make_task(item)
            if task is None:
                continue
            pending[executor.submit(task)] = (item, task)
        if not pending:
            break
        done, _ = executor.wait_first(set(pending))
        for future in done:
            item, task = pending.pop(future)
            result = _outcome(future, task)
            if isinstance(executor, _PoolExecutor) and _is_broken_pool(result):
                broken.append((item, task))
                continue
            on_result(item, result)
        if broken and isinstance(executor, _PoolExecutor):
            # a worker died: the pool is unusable; finish the rest in a new pool, and re-run the
            # tasks that were in flight one by one so that only the culprit fails
            log.warning("a worker process died; re-running the %d task(s) it took down, one at a time",
                        len(broken) + len(pending))
            for future, (item, task) in list(pending.items()):
                broken.append((item, task))
            pending.clear()
            executor.close()
            executor.__init__(executor.workers)
            for item, task in broken:
                on_result(item, _run_isolated(task))
            broken.clear()


class _Executors:
    """Creates the executor when the first tasks need it (sized for them); closes it at the end."""

    def __init__(self, settings: Settings):
        self.settings = settings
        self.executor = None

    def get(self, n_tasks: int):
        if self.executor is None:
            self.executor = _make_executor(self.settings, n_tasks)
            log.info("running on %s", self.executor.label)
        return self.executor

    @property
    def label(self) -> str:
        return self.executor.label if self.executor is not None else "nothing to run"

    def close(self):
        if self.executor is not None:
            self.executor.close()


def _make_executor(settings: Settings, n_tasks: int):
    scheduler = settings.get("batch.scheduler")
    if scheduler:
        if settings.origins.get("batch.workers") != "default":
            log.info("workers = %s is not used with a scheduler: the cluster's workers run the tasks",
                     settings.get("batch.workers"))
        return _DaskExecutor(scheduler)
    workers = settings.get("batch.workers") or _cores()
    workers = max(1, min(workers, n_tasks))
    return _SerialExecutor() if workers == 1 else _PoolExecutor(workers)


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


# ============================================================================= lock

class LockedError(ProcessingError):
    """Another run holds the output directory's lock (exit 1: this run did nothing)."""


@contextlib.contextmanager
def batch_lock(directory: Path, wait: bool = False, timeout_s: float = 0.0):
    """Hold ``directory/.batch.lock`` (``fcntl.flock``, exclusive) for the block.

    Held by another process: wait for it when ``wait`` (at most ``timeout_s`` seconds, 0 = no
    limit), else raise :class:`LockedError` naming the holder. The file stays in place (removing
    it would let a third run lock a different file); the kernel releases the lock when the
    holder exits, however it exits.
    """
    import fcntl

    path = directory / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _lock_holder(fd)
            if not wait:
                raise LockedError(f"{path} is held by another trackproc batch run ({holder}); this run did "
                                  "nothing: try again later, or use --wait") from None
            log.info("waiting for %s (held by %s)", path, holder)
            deadline = time.monotonic() + timeout_s if timeout_s > 0 else None
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if deadline is not None and time.monotonic() > deadline:
                        raise LockedError(f"{path} is still held by another trackproc batch run ({holder}) "
                                          f"after {timeout_s:g} s; this run did nothing") from None
                    time.sleep(0.1)
        os.ftruncate(fd, 0)
        os.pwrite(fd, (f"pid {os.getpid()} on {socket.gethostname()} since {_now()}\n").encode(), 0)
        yield path
    finally:
        os.close(fd)  # releases the lock


def _lock_holder(fd: int) -> str:
    try:
        text = os.pread(fd, 200, 0).decode("utf-8", errors="replace").strip()
    except OSError:
        text = ""
    return text or "holder unknown"


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


# ============================================================================= inputs and keys

@dataclass
class InputFile:
    """An input file found by the patterns: result ``name`` and ``path``."""

    name: str
    path: str


_MAGIC = set("*?[")


def discover(entries: Sequence[str], patterns: Sequence[str], exclude: Sequence[str] = ()) -> list:
    """The input files of directories, files and globs, in name order.

    A directory gives its files matching ``patterns`` (not recursive; use a ``**`` glob for
    that); a glob gives the regular files it matches; hidden files are left out, as are
    ``exclude`` (the output directory, the stations and state files). Result names are paths
    relative to the directory (or the glob's fixed part) without the suffix.
    """
    excluded = [os.path.realpath(p) for p in exclude if p]
    found: dict = {}
    for entry in entries:
        if any(ch in _MAGIC for ch in entry):
            base = _glob_base(entry)
            paths = sorted(glob.glob(entry, recursive=True))
            if not paths:
                log.warning("no input file matches %s", entry)
        elif os.path.isdir(entry):
            base = entry
            paths = sorted({p for pattern in patterns for p in glob.glob(os.path.join(glob.escape(entry), pattern))})
            if not paths:
                log.warning("no input file in %s (patterns %s)", entry, ", ".join(patterns))
        elif os.path.isfile(entry):
            base = os.path.dirname(entry) or "."
            paths = [entry]
        else:
            raise InputError("input not found", file=entry, expected="a directory, a file or a glob")
        for path in paths:
            real = os.path.realpath(path)
            if not os.path.isfile(path) or os.path.basename(path).startswith("."):
                continue
            if any(real == e or real.startswith(e + os.sep) for e in excluded):
                continue
            rel = os.path.relpath(path, base)
            name = os.path.splitext(rel)[0].replace(os.sep, "/")
            if real in found:
                continue
            found[real] = InputFile(name, path)
    by_name: dict = {}
    for item in found.values():
        other = by_name.get(item.name)
        if other is not None:
            raise InputError("two inputs would give the same result name", file=item.path, found=item.name,
                             expected=f"a name different from {other.path}'s: rename one, or give them separate "
                                      "sub-directories under one input directory glob")
        by_name[item.name] = item
    return [by_name[n] for n in sorted(by_name)]


def _glob_base(pattern: str) -> str:
    parts = Path(pattern).parts
    fixed = []
    for part in parts:
        if any(ch in _MAGIC for ch in part):
            break
        fixed.append(part)
    return str(Path(*fixed)) if fixed else "."


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _key(doc: dict) -> str:
    return sha256(json.dumps(doc, sort_keys=True, separators=(",", ":"), default=str).encode())


def step_options(settings: Settings, steps: Sequence[str], file_hashes: dict) -> dict:
    """What the content key covers besides the input: the settings of ``steps`` (one section
    each) with the file paths left out, and the content hash of each of those files (so a
    stations table moved elsewhere changes nothing, one edited redoes everything)."""
    out = {}
    for name in steps:
        section = settings.section(name) if name in settings.values else {}
        out[name] = {k: v for k, v in section.items() if f"{name}.{k}" not in file_hashes}
    return {"options": out, "files": {k: file_hashes.get(k) for k in sorted(file_hashes)}}


# ============================================================================= records

@dataclass
class Record:
    """One line of the summary: an input (``task="pass"``) or a window (``task="estimate"``)."""

    task: str
    name: str
    status: str
    skipped: bool
    key: str
    path: Optional[str] = None
    numbers: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    outputs: list = field(default_factory=list)
    error: Optional[str] = None
    error_type: Optional[str] = None
    seconds: float = 0.0
    members: list = field(default_factory=list)
    table_key: str = ""  # the content key of the pass table (what a window's key covers)

    def as_dict(self) -> dict:
        out = dataclasses.asdict(self)
        del out["table_key"]
        if self.task == "pass":
            del out["members"]
        return out

    def csv_row(self) -> dict:
        row = {c: self.numbers.get(c) for c in CSV_COLUMNS}
        row.update(task=self.task, input=self.name, status=self.status, skipped=self.skipped,
                   output=self.outputs[0] if self.outputs else None, error=self.error)
        return row


def _manifest_path(out: Path, directory: str, name: str) -> Path:
    return out / directory / f"{name}{MANIFEST_SUFFIX}"


def _read_manifest(path: Path) -> Optional[dict]:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _up_to_date(manifest: Optional[dict], key: str, out: Path, retry_failed: bool) -> bool:
    if not manifest or manifest.get("key") != key or manifest.get("trackproc_version") != __version__:
        return False
    if manifest.get("status") == "failed":
        return not retry_failed and manifest.get("error_type") in ("input", "processing")
    for rel, info in (manifest.get("outputs") or {}).items():
        try:
            if (out / rel).stat().st_size != info.get("bytes"):
                return False
        except OSError:
            return False
    return manifest.get("status") == "ok"


def _record_from_manifest(manifest: dict, task: str) -> Record:
    return Record(task=task, name=manifest["name"], status=manifest["status"], skipped=True, key=manifest["key"],
                  path=manifest.get("path"), numbers=manifest.get("numbers") or {},
                  details=manifest.get("details") or {}, warnings=manifest.get("warnings") or [],
                  outputs=list(manifest.get("outputs") or {}), error=manifest.get("error"),
                  error_type=manifest.get("error_type"), members=manifest.get("members") or [],
                  table_key=manifest.get("table_key") or manifest["key"])


def _stored_stage(manifest: Optional[dict], table_key: str, out: Path) -> Optional[dict]:
    """The table stage of an up-to-date-but-for-the-side-steps result (same table key, ok, its
    table outputs in place), from which only the side steps need to run; else None. A result made
    without side steps (its key is its table key) is all table stage."""
    if (not manifest or manifest.get("status") != "ok" or manifest.get("trackproc_version") != __version__
            or (manifest.get("table_key") or manifest.get("key")) != table_key):
        return None
    outputs = manifest.get("outputs") or {}
    stage = manifest.get("table_stage")
    if not isinstance(stage, dict):
        if manifest.get("key") != table_key:
            return None
        stage = {"numbers": manifest.get("numbers") or {}, "details": manifest.get("details") or {},
                 "warnings": manifest.get("warnings") or [], "outputs": sorted(outputs)}
    for rel in stage.get("outputs") or ():
        info = outputs.get(rel)
        try:
            if not info or (out / rel).stat().st_size != info.get("bytes"):
                return None
        except OSError:
            return None
    return stage


def _store(out: Path, directory: str, result: TaskResult, *, task: str, path: Optional[str], settings_doc: dict,
           members: Sequence = (), old: Optional[dict] = None) -> Record:
    """Write a task's outputs (atomically) then its manifest; remove a failed input's old outputs.
    When only the side steps ran (``result.reused``), the stored table stage's outputs stay as
    they are and are listed again."""
    outputs = {}
    for suffix, data in sorted(result.outputs.items()):
        rel = f"{directory}/{result.name}{suffix}"
        write_bytes(out / rel, data)
        outputs[rel] = {"bytes": len(data), "sha256": sha256(data)}
    stage = result.stage
    if stage is not None and result.reused:
        for rel in stage["outputs"]:
            outputs.setdefault(rel, (old or {}).get("outputs", {}).get(rel))
        outputs = dict(sorted(outputs.items()))
    elif stage is not None:
        stage = {**stage, "outputs": [f"{directory}/{result.name}{suffix}" for suffix in stage["outputs"]]}
    if old and result.status == "failed" and result.error_type != "internal":
        for rel in (old.get("outputs") or {}):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(out / rel)
                log.info("removed %s (its input now fails)", rel)
    elif old and result.status == "ok":  # e.g. a .refined.json when refine left the chain
        for rel in (old.get("outputs") or {}):
            if rel not in outputs:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(out / rel)
                    log.info("removed %s (no longer made by the chain)", rel)
    record = Record(task=task, name=result.name, status=result.status, skipped=False, key=result.key, path=path,
                    numbers=result.numbers, details=result.details, warnings=result.warnings,
                    outputs=list(outputs), error=result.error, error_type=result.error_type,
                    seconds=round(result.seconds, 3), members=list(members),
                    table_key=result.table_key or result.key)
    if result.error_type == "internal":  # not recorded: the next run tries again
        return record
    manifest = {"trackproc_version": __version__, "key": result.key, "name": result.name, "path": path,
                "status": result.status, "error": result.error, "error_type": result.error_type,
                "numbers": result.numbers, "details": result.details, "warnings": result.warnings,
                "outputs": outputs, "members": list(members), "settings": settings_doc, "finished_utc": _now()}
    if task == "pass":
        manifest["table_key"] = result.table_key or result.key
        if stage is not None:
            manifest["table_stage"] = stage
    write_text(_manifest_path(out, directory, result.name), dumps(manifest))
    return record


# ============================================================================= the run

@dataclass
class BatchResult:
    """``inputs`` and ``windows`` (:class:`Record`), ``exit_code``, ``counts``, ``summary`` (the
    summary.json document), ``executor`` (how the work ran)."""

    inputs: list
    windows: list
    exit_code: int
    counts: dict
    summary: dict
    executor: str


def run_batch(settings: Settings, progress: Optional[Callable] = None) -> BatchResult:
    """Run the configured batch (see the module docstring); ``progress(done, total, failed)``
    is called as tasks finish. Raises :class:`InputError` for usage errors before any work and
    :class:`LockedError` when another run holds the output directory."""
    started, t0 = _now(), time.perf_counter()
    chain = make_chain(settings.get("batch.steps"))
    output = settings.get("batch.output")
    if not output or output == "-":
        raise InputError("no output directory", column="-o/--output", found=output,
                         expected="-o DIR, output = \"DIR\" in [batch], or TRACKPROC_BATCH_OUTPUT")
    scheduler = settings.get("batch.scheduler")
    if scheduler and "://" not in scheduler:
        raise InputError("invalid scheduler address", column="--scheduler", found=scheduler,
                         expected="tcp://HOST:PORT (a Dask distributed scheduler)")
    entries = settings.get("batch.inputs")
    if not entries:
        raise InputError("no inputs", column="--input",
                         expected="--input DIR|GLOB, inputs = [...] in [batch], or TRACKPROC_BATCH_INPUTS")
    if "estimate" in chain.names and not settings.get("estimate.initial"):
        raise InputError("the estimate step needs an initial state", column="--initial",
                         expected="--initial STATE.json|TLE, or initial = \"...\" in [estimate]")
    if "refine" in chain.names:
        _check_refine_settings(settings)
    files, paths, hashes = _read_files(settings, chain)
    if "refine" in chain.names:  # a state file every input would fail on: a usage error, now
        _initial_state(files["refine.initial"], paths["refine.initial"], None)
    out = Path(output)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output directory: {exc.strerror}", file=output) from None
    with batch_lock(out, settings.get("batch.wait"), settings.get("batch.wait_timeout_s")):
        _remove_leftovers(out)
        inputs = discover(entries, settings.get("batch.patterns"),
                          exclude=[output] + [p for p in paths.values() if p])
        executors = _Executors(settings)
        try:
            records = _run_inputs(settings, chain, inputs, files, paths, hashes, out, executors, progress)
            windows = (_run_windows(settings, chain, records, files, paths, hashes, out, executors)
                       if chain.window_steps else [])
        finally:
            executors.close()
        result = _finish(settings, chain, records, windows, out, started, t0, executors.label)
    return result


def _check_refine_settings(settings: Settings) -> None:
    """Settings of the refine step that would fail every input: usage errors before any work."""
    if not settings.get("refine.initial"):
        raise InputError("the refine step needs a stale state", column="--refine-initial",
                         expected="--refine-initial STATE.json|TLE, or initial = \"...\" in [refine]")
    if settings.get("refine.eop") is not None and settings.get("refine.dut1") is not None:
        raise InputError("give either an EOP file or UT1-UTC, not both", column="refine.eop / refine.dut1",
                         expected="one of --refine-eop, --refine-dut1")
    if settings.get("refine.apriori") is False and settings.get("refine.apriori_sigma"):
        raise InputError("a-priori sigmas without the a-priori", column="refine.apriori_sigma",
                         found=", ".join(settings.get("refine.apriori_sigma")),
                         expected="apriori = true (or unset), or no apriori_sigma")


def _read_files(settings: Settings, chain: Chain):
    """Bytes, paths and hashes of the files the chain's settings name (read once, here)."""
    files, paths, hashes = {}, {}, {}
    for name in sorted(set(chain.files("input")) | set(chain.files("window"))):
        path = settings.get(name)
        paths[name] = path
        if path is None:
            files[name] = None
            hashes[name] = None
            continue
        try:
            data = Path(path).read_bytes()
        except FileNotFoundError:
            raise InputError("file not found", file=path, column=name) from None
        except IsADirectoryError:
            raise InputError("is a directory, expected a file", file=path, column=name) from None
        except PermissionError:
            raise InputError("permission denied", file=path, column=name) from None
        files[name] = data if not name.endswith(".eop") else None  # the EOP file is read by its own reader
        hashes[name] = "sha256:" + sha256(data)
    return files, paths, hashes


def _remove_leftovers(out: Path) -> None:
    """Temporary files of an interrupted run (``.NAME.XXXX.tmp``): no other run is writing now."""
    removed = 0
    candidates = list(out.glob(".*.tmp"))
    for directory in (out / PASSES_DIR, out / ESTIMATES_DIR):
        if directory.is_dir():
            candidates.extend(directory.rglob(".*.tmp"))
    for path in candidates:
        if path.is_file():
            with contextlib.suppress(OSError):
                path.unlink()
                removed += 1
    if removed:
        log.info("removed %d temporary file(s) left by an interrupted run", removed)


def _input_keys(settings, chain, hashes) -> Callable:
    """``keys(input bytes) -> (key, table key)``.

    The table key covers the input, the table steps' settings and files and the version (with no
    side steps it is the key, as it always was); the key covers the table key and the side
    steps' settings and files, so changing only those redoes only the side steps (from the
    stored table) and leaves the windows, which read the table, up to date.
    """
    table_doc = step_options(settings, chain.table_steps, {k: hashes[k] for k in chain.files("table")})
    base = {"trackproc": __version__, "steps": list(chain.table_steps), "reads_raw": chain.reads_raw, **table_doc}
    side = None
    if chain.side_steps:
        side = {"trackproc": __version__, "steps": list(chain.side_steps),
                **step_options(settings, chain.side_steps, {k: hashes[k] for k in chain.files("side")})}

    def keys(data: bytes) -> tuple:
        table_key = _key({**base, "input_sha256": sha256(data)})
        return (table_key if side is None else _key({**side, "table_key": table_key})), table_key

    return keys


def _run_inputs(settings, chain, inputs, files, paths, hashes, out, executors, progress):
    input_files = {k: hashes[k] for k in chain.files("input")}
    options_doc = step_options(settings, chain.input_steps, input_files)
    keys = _input_keys(settings, chain, hashes)
    force, retry = settings.get("batch.force"), settings.get("batch.retry_failed")
    records: dict = {}
    todo = []
    manifests = {}
    for item in inputs:
        try:
            data = Path(item.path).read_bytes()
        except OSError as exc:
            records[item.name] = Record(task="pass", name=item.name, status="failed", skipped=False, key="",
                                        path=item.path, error=f"{item.path}: cannot read: {exc.strerror}",
                                        error_type="internal")
            log.error("%s: failed: cannot read: %s", item.path, exc.strerror)
            continue
        key, table_key = keys(data)
        manifest = _read_manifest(_manifest_path(out, PASSES_DIR, item.name))
        manifests[item.name] = manifest
        if not force and _up_to_date(manifest, key, out, retry):
            records[item.name] = _record_from_manifest(manifest, "pass")
            continue
        stage = None if force or not chain.side_steps else _stored_stage(manifest, table_key, out)
        todo.append((item, key, table_key, stage))
    total = len(inputs)
    n_skipped = len(records)
    n_side = sum(stage is not None for *_, stage in todo)
    log.info("%d input(s): %d up to date, %d to do (steps %s%s)", total, n_skipped, len(todo),
             " -> ".join(chain.names), f"; {n_side} of them {', '.join(chain.side_steps)} only, from their stored "
                                        f"{' and '.join(chain.table_steps) or 'pass'} results" if n_side else "")
    done = [n_skipped, sum(r.status == "failed" for r in records.values())]
    if progress:
        progress(done[0], total, done[1])
    options = {name: settings.section(name) for name in chain.input_steps}
    task_files = {k: files[k] for k in chain.files("input")}
    task_paths = {k: paths[k] for k in chain.files("input")}
    def make_task(entry):
        item, key, table_key, stage = entry
        if stage is not None:  # only the side steps, on the stored pass table (unless it changed since)
            rel = f"{PASSES_DIR}/{item.name}.parquet"
            info = (manifests[item.name].get("outputs") or {}).get(rel) or {}
            with contextlib.suppress(OSError):
                table = (out / rel).read_bytes()
                if sha256(table) == info.get("sha256"):
                    return Task(kind="input", name=item.name, key=key, steps=(), options=options, files=task_files,
                                paths=task_paths, source=item.path, data=table, reads_raw=False,
                                side_steps=chain.side_steps, stage=stage, table_key=table_key)
        try:
            data = Path(item.path).read_bytes()
        except OSError as exc:
            records[item.name] = Record(task="pass", name=item.name, status="failed", skipped=False, key=key,
                                        path=item.path, error=f"{item.path}: cannot read: {exc.strerror}",
                                        error_type="internal")
            _log_record(records[item.name])
            done[0] += 1
            done[1] += 1
            return None
        key, table_key = keys(data)  # the bytes sent are the bytes hashed
        return Task(kind="input", name=item.name, key=key, steps=chain.table_steps, options=options,
                    files=task_files, paths=task_paths, source=item.path, data=data, reads_raw=chain.reads_raw,
                    side_steps=chain.side_steps, table_key=table_key)

    def on_result(entry, result: TaskResult):
        item = entry[0]
        record = _store(out, PASSES_DIR, result, task="pass", path=item.path, old=manifests.get(item.name),
                        settings_doc={"steps": list(chain.input_steps), **options_doc})
        records[item.name] = record
        _log_record(record, result)
        done[0] += 1
        done[1] += record.status == "failed"
        if progress:
            progress(done[0], total, done[1])

    if todo:
        _execute(executors.get(len(todo)), todo, make_task, on_result)
    return [records[n] for n in sorted(records)]


def _log_record(record: Record, result: Optional[TaskResult] = None) -> None:
    what = "estimate " if record.task == "estimate" else ""
    if record.status == "ok":
        n = record.numbers
        if record.task == "pass":
            refined = ""
            if n.get("refined_pass"):
                refined = (f"; refined {n['refined_pass']} in {n.get('iterations')} iterations, residual RMS "
                           f"{n.get('residual_rms') or math.nan:.4g} {n.get('residual_rms_unit')}, sigma RTN "
                           + "/".join(f"{n.get(k) or math.nan:.3g}" for k in ("sigma_radial_m", "sigma_along_m",
                                                                                "sigma_cross_m")) + " m")
            log.info("%s: ok (%s samples, %s pass(es)%s%s) in %.2f s", record.name, n.get("samples"), n.get("passes"),
                     f", {n['kind']} RMS {n['rms']:.4g} {n['rms_unit']}" if n.get("rms") is not None else "",
                     refined, record.seconds)
        else:
            log.info("estimate %s: ok (%s inputs, %s samples, %s iterations, WRMS %.3g) in %.2f s", record.name,
                     n.get("inputs"), n.get("samples"), n.get("iterations"), n.get("wrms") or math.nan,
                     record.seconds)
        for warning in record.warnings:
            log.warning("%s%s: %s", what, record.name, warning)
    else:
        log.error("%s%s: failed: %s", what, record.name, record.error)
        if result is not None and result.trace:
            log.debug("%s", result.trace)


def window_of(start_utc: str, window_s: float) -> tuple:
    """(name, start) of the window holding ``start_utc``: windows of ``window_s`` seconds aligned
    on 1970-01-01T00:00:00Z (86400: UTC days, named YYYY-MM-DD); ``window_s = 0``: ``all``."""
    if not window_s:
        return "all", None
    import calendar

    seconds = calendar.timegm(time.strptime(start_utc[:19], "%Y-%m-%dT%H:%M:%S"))
    begin = math.floor(seconds / window_s) * window_s
    stamp = time.gmtime(begin)
    if window_s % 86400 == 0:
        return time.strftime("%Y-%m-%d", stamp), begin
    return time.strftime("%Y-%m-%dT%H%M%SZ", stamp), begin


def _run_windows(settings, chain, records, files, paths, hashes, out, executors):
    window_s = settings.get("estimate.window_s")
    groups: dict = {}
    for record in records:
        if record.status == "ok" and record.numbers.get("start_utc"):
            groups.setdefault(window_of(record.numbers["start_utc"], window_s)[0], []).append(record)
    window_files = {k: hashes[k] for k in chain.files("window")}
    options_doc = step_options(settings, chain.window_steps, window_files)
    options = {name: settings.section(name) for name in chain.window_steps}
    force, retry = settings.get("batch.force"), settings.get("batch.retry_failed")
    min_inputs = settings.get("estimate.min_inputs")
    results: dict = {}
    todo = []
    manifests = {}
    for name, members in sorted(groups.items()):
        member_keys = [[r.name, r.table_key or r.key] for r in members]  # a window reads the pass tables
        key = _key({"trackproc": __version__, "steps": list(chain.window_steps), **options_doc,
                    "members": member_keys})
        manifest = _read_manifest(_manifest_path(out, ESTIMATES_DIR, name))
        manifests[name] = manifest
        if len(members) < min_inputs:
            results[name] = Record(task="estimate", name=name, status="failed", skipped=False, key=key,
                                   error=f"{len(members)} processed input(s) in the window; at least {min_inputs} "
                                         "needed (estimate.min_inputs)", error_type="processing",
                                   members=[r.name for r in members])
            _log_record(results[name])
            continue
        if not force and _up_to_date(manifest, key, out, retry):
            results[name] = _record_from_manifest(manifest, "estimate")
            continue
        todo.append((name, key, members))
    log.info("%d estimate window(s): %d up to date, %d to do", len(groups), len(groups) - len(todo), len(todo))
    if not todo:
        return [results[n] for n in sorted(results)]
    task_files = {k: files[k] for k in chain.files("window")}
    task_paths = {k: paths[k] for k in chain.files("window")}

    def make_task(entry):
        name, key, members = entry
        data = [(f"{PASSES_DIR}/{r.name}.parquet", (out / PASSES_DIR / f"{r.name}.parquet").read_bytes())
                for r in members]
        return Task(kind="window", name=name, key=key, steps=chain.window_steps, options=options, files=task_files,
                    paths=task_paths, members=data)

    def on_result(entry, result: TaskResult):
        name, key, members = entry
        record = _store(out, ESTIMATES_DIR, result, task="estimate", path=None, old=manifests.get(name),
                        settings_doc={"steps": list(chain.window_steps), **options_doc},
                        members=[r.name for r in members])
        results[name] = record
        _log_record(record, result)

    _execute(executors.get(len(todo)), todo, make_task, on_result)
    return [results[n] for n in sorted(results)]


def _finish(settings, chain, records, windows, out, started, t0, label) -> BatchResult:
    units = records + windows
    failed = sum(r.status == "failed" for r in units)
    ok = len(units) - failed
    exit_code = EXIT_OK if failed == 0 else EXIT_PROCESSING if ok == 0 else EXIT_PARTIAL
    counts = {"inputs": len(records), "inputs_ok": sum(r.status == "ok" for r in records),
              "inputs_failed": sum(r.status == "failed" for r in records),
              "inputs_skipped": sum(r.skipped for r in records),
              "windows": len(windows), "windows_ok": sum(r.status == "ok" for r in windows),
              "windows_failed": sum(r.status == "failed" for r in windows),
              "windows_skipped": sum(r.skipped for r in windows)}
    seconds = time.perf_counter() - t0
    summary = {"trackproc_version": __version__, "command": "batch", "started_utc": started,
               "finished_utc": _now(), "seconds": round(seconds, 3), "exit_code": exit_code,
               "executor": label, "steps": list(chain.names), "counts": counts,
               "settings": {s: settings.section(s) for s in settings.values},
               "settings_origin": dict(settings.origins), "config_file": settings.config_file,
               "inputs": [r.as_dict() for r in records], "estimates": [r.as_dict() for r in windows]}
    write_text(out / SUMMARY_JSON, dumps(summary))
    write_text(out / SUMMARY_CSV, summary_csv(units))
    log.info("done in %.1f s: %d input(s) ok, %d failed, %d up to date%s -> %s (exit %d)", seconds,
             counts["inputs_ok"], counts["inputs_failed"], counts["inputs_skipped"],
             (f"; {counts['windows_ok']} estimate window(s) ok, {counts['windows_failed']} failed"
              if windows else ""), out / SUMMARY_JSON, exit_code)
    return BatchResult(inputs=records, windows=windows, exit_code=exit_code, counts=counts, summary=summary,
                       executor=label)


def summary_csv(records: Sequence[Record]) -> str:
    """summary.csv: :data:`CSV_COLUMNS`, one row per record; floats as the shortest exact text."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for record in records:
        row = record.csv_row()
        writer.writerow([_cell(row[c]) for c in CSV_COLUMNS])
    return buffer.getvalue()


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    return str(value)


__all__ = ["CHAIN", "STEPS", "Step", "register", "make_chain", "InputContext", "WindowContext", "Task",
           "TaskResult", "run_task", "run_batch", "BatchResult", "Record", "batch_lock", "LockedError", "discover",
           "window_of", "summary_csv", "refine_pass", "REFINE_PASS_RULE"]
