"""What ``trackproc batch`` reports: the log line of each result and the summary files.

``OUTPUT/summary.json`` and ``OUTPUT/summary.csv``: one record per input and per window.
Exit status (:attr:`BatchResult.exit_code`): 0 every input and window ok, 3 some failed, 1 all
failed.

Names come from the inputs (file names, and error messages quoting them), and a file name may
hold a newline: every message of the ``trackproc.batch`` logger (and, through the CLI's
handler, of any trackproc logger during a batch) and every cell of summary.csv is one line
(:func:`printable`), so no input can forge a log line or a summary row. The JSON files escape
control characters by themselves.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import time
import unicodedata
from dataclasses import dataclass
from typing import Optional, Sequence

from trackproc import __version__
from trackproc.errors import EXIT_OK, EXIT_PARTIAL, EXIT_PROCESSING
from trackproc.io.atomic import write_text
from trackproc.io.jsonutil import dumps
from trackproc.pipeline.batch.store import CSV_COLUMNS, Record, utc_now
from trackproc.pipeline.batch.tasks import TaskResult

log = logging.getLogger("trackproc.batch")

SUMMARY_JSON = "summary.json"
SUMMARY_CSV = "summary.csv"
#: Unicode categories escaped by :func:`printable`: control and format characters (newline,
#: escape, bidirectional overrides), line and paragraph separators.
UNPRINTABLE = ("Cc", "Cf", "Zl", "Zp")


def printable(text) -> str:
    """``str(text)`` on one line: each character of :data:`UNPRINTABLE` as its Python escape
    (``\\n``, ``\\x1b``, ``\\u2028``); everything else as it is."""
    text = str(text)
    if text.isprintable():
        return text
    return "".join(repr(ch)[1:-1] if unicodedata.category(ch) in UNPRINTABLE else ch for ch in text)


class OneLineFilter(logging.Filter):
    """Makes each message of the logger it filters one line (:func:`printable`)."""

    def filter(self, record):
        message = record.getMessage()
        safe = printable(message)
        if safe != message:
            record.msg, record.args = safe, None
        return True


log.addFilter(OneLineFilter())  # every module of the batch logs on this logger


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


def log_record(record: Record, result: Optional[TaskResult] = None) -> None:
    """The log lines of one result: ok with its key numbers and its warnings, or failed with the
    reason (and, at debug level, the traceback of an unexpected failure)."""
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
            if n.get("quality"):
                refined += (f", quality {n['quality']}"
                            + (f" ({n['quality_reasons']})" if n.get("quality_reasons") else ""))
            log.info("%s: ok (%s samples, %s pass(es)%s%s) in %.2f s", record.name, n.get("samples"), n.get("passes"),
                     f", {n['kind']} RMS {n['rms']:.4g} {n['rms_unit']}" if n.get("rms") is not None else "",
                     refined, record.seconds)
        else:
            quality = (f", quality {n['quality']}" + (f" ({n['quality_reasons']})" if n.get("quality_reasons") else "")
                       if n.get("quality") else "")
            log.info("estimate %s: ok (%s inputs, %s samples, %s iterations, WRMS %.3g%s) in %.2f s", record.name,
                     n.get("inputs"), n.get("samples"), n.get("iterations"), n.get("wrms") or math.nan, quality,
                     record.seconds)
        for warning in record.warnings:
            log.warning("%s%s: %s", what, record.name, warning)
    else:
        log.error("%s%s: failed: %s", what, record.name, record.error)
        if result is not None and result.trace:
            for line in result.trace.splitlines():  # one record per line: the filter keeps each one line
                log.debug("%s", line)


def finish(settings, chain, records, windows, out, started, t0, label, reporter=None) -> BatchResult:
    """The exit status and counts of the run; writes summary.json and summary.csv, then calls
    ``reporter(out, summary)`` (report.html); a reporter's failure is logged, the run's status stands."""
    units = records + windows
    failed = sum(r.status == "failed" for r in units)
    # a solution its own checks reject (or, with --strict, call suspect) counts against the run as
    # a failure does (exit 3, or 1 when nothing else succeeded), its outputs written for inspection
    refused_verdicts = ("rejected", "suspect") if settings.section("batch").get("strict") else ("rejected",)
    flagged = sum(r.status == "ok" and r.numbers.get("quality") in refused_verdicts for r in units)
    ok = len(units) - failed - flagged
    exit_code = EXIT_OK if failed + flagged == 0 else EXIT_PROCESSING if ok == 0 else EXIT_PARTIAL
    counts = {"inputs": len(records), "inputs_ok": sum(r.status == "ok" for r in records),
              "inputs_failed": sum(r.status == "failed" for r in records),
              "inputs_skipped": sum(r.skipped for r in records),
              "windows": len(windows), "windows_ok": sum(r.status == "ok" for r in windows),
              "windows_failed": sum(r.status == "failed" for r in windows),
              "windows_skipped": sum(r.skipped for r in windows),
              "quality_suspect": sum(r.status == "ok" and r.numbers.get("quality") == "suspect" for r in units),
              "quality_rejected": sum(r.status == "ok" and r.numbers.get("quality") == "rejected" for r in units),
              "quality_counted_as_failed": flagged}
    seconds = time.perf_counter() - t0
    summary = {"trackproc_version": __version__, "command": "batch", "started_utc": started,
               "finished_utc": utc_now(), "seconds": round(seconds, 3), "exit_code": exit_code,
               "executor": label, "steps": list(chain.names), "counts": counts,
               "settings": {s: settings.section(s) for s in settings.values},
               "settings_origin": dict(settings.origins), "config_file": settings.config_file,
               "inputs": [r.as_dict() for r in records], "estimates": [r.as_dict() for r in windows]}
    write_text(out / SUMMARY_JSON, dumps(summary))
    write_text(out / SUMMARY_CSV, summary_csv(units))
    if reporter is not None:
        try:
            reporter(out, summary)
        except Exception as exc:  # the summaries are written: the report is the extra
            log.error("report not written: %s: %s", type(exc).__name__, exc)
    log.info("done in %.1f s: %d input(s) ok, %d failed, %d up to date%s%s -> %s (exit %d)", seconds,
             counts["inputs_ok"], counts["inputs_failed"], counts["inputs_skipped"],
             (f"; {counts['windows_ok']} estimate window(s) and filter run(s) ok, {counts['windows_failed']} failed"
              if any(r.task == "filter" for r in windows) else
              f"; {counts['windows_ok']} estimate window(s) ok, {counts['windows_failed']} failed" if windows else ""),
             (f"; {flagged} solution(s) counted as failed by their quality verdict ({'/'.join(refused_verdicts)})"
              if flagged else ""), out / SUMMARY_JSON, exit_code)
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
    return printable(value)
