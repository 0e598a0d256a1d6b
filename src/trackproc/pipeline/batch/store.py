"""What ``trackproc batch`` keeps in the output directory: content keys, records and manifests.

The content key of a result is the SHA-256 of the input's bytes, the settings of the steps that
produced it (the content of every file they name) and the trackproc version (see
:mod:`trackproc.pipeline.batch`). Every file goes through :mod:`trackproc.io.atomic`; a manifest
(``<name>.batch.json``) is written after its outputs, so an interrupted run leaves complete
results and the next one redoes only the rest.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence

from trackproc import __version__
from trackproc.io.atomic import write_bytes, write_text
from trackproc.io.jsonutil import dumps_compact
from trackproc.pipeline.batch.config import Settings
from trackproc.pipeline.batch.tasks import TaskResult

log = logging.getLogger("trackproc.batch")

PASSES_DIR = "passes"
ESTIMATES_DIR = "estimates"
MANIFEST_SUFFIX = ".batch.json"
#: Columns of summary.csv, one row per input ("pass") and per window ("estimate").
CSV_COLUMNS = ("task", "input", "status", "skipped", "samples", "passes", "stations", "start_utc", "end_utc",
               "fits_ok", "fits_suspect", "fits_failed", "kind", "rms", "rms_unit", "tca_utc", "tca_sigma_s",
               "fca_hz", "refined_pass", "traverse_utc", "converged", "iterations", "wrms", "residual_rms",
               "residual_rms_unit", "sigma_radial_m", "sigma_along_m", "sigma_cross_m", "quality", "quality_reasons",
               "decision", "output", "error")


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def content_key(doc: dict) -> str:
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
        # the fields as they are, not dataclasses.asdict's deep copy (~0.3 ms of CPU a pass in the
        # summary): they hold JSON values only (json_ready's, or a manifest's), which the summary's
        # writer copies again, and nothing changes them after the run
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        del out["table_key"]
        if self.task == "pass":
            del out["members"]
        return out

    def csv_row(self) -> dict:
        row = {c: self.numbers.get(c) for c in CSV_COLUMNS}
        row.update(task=self.task, input=self.name, status=self.status, skipped=self.skipped,
                   output=self.outputs[0] if self.outputs else None, error=self.error)
        return row


def manifest_path(out: Path, directory: str, name: str) -> Path:
    return out / directory / f"{name}{MANIFEST_SUFFIX}"


def read_manifest(path: Path) -> Optional[dict]:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def up_to_date(manifest: Optional[dict], key: str, out: Path, retry_failed: bool) -> bool:
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


def record_from_manifest(manifest: dict, task: str) -> Record:
    return Record(task=task, name=manifest["name"], status=manifest["status"], skipped=True, key=manifest["key"],
                  path=manifest.get("path"), numbers=manifest.get("numbers") or {},
                  details=manifest.get("details") or {}, warnings=manifest.get("warnings") or [],
                  outputs=list(manifest.get("outputs") or {}), error=manifest.get("error"),
                  error_type=manifest.get("error_type"), members=manifest.get("members") or [],
                  table_key=manifest.get("table_key") or manifest["key"])


def stored_stage(manifest: Optional[dict], table_key: str, out: Path) -> Optional[dict]:
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


def store_result(out: Path, directory: str, result: TaskResult, *, task: str, path: Optional[str], settings_doc: dict,
           members: Sequence = (), old: Optional[dict] = None) -> Record:
    """Write a task's outputs (atomically) then its manifest; remove a failed input's old outputs.
    When only the side steps ran (``result.reused``), the stored table stage's outputs stay as
    they are and are listed again. ``settings_doc`` is JSON-ready (``json_ready``'s output)."""
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
                "outputs": outputs, "members": list(members), "settings": settings_doc, "finished_utc": utc_now()}
    if task == "pass":
        manifest["table_key"] = result.table_key or result.key
        if stage is not None:
            manifest["table_stage"] = stage
    write_text(manifest_path(out, directory, result.name), manifest_text(manifest))
    return record


def manifest_text(manifest: dict) -> str:
    """The manifest's one line (read by runs, not people): its parts are JSON-ready already (a
    task's numbers and details are ``json_ready``'s output in the worker, the settings document
    is made ready once a run, the rest are strings, numbers and lists of them), so they go to the
    C encoder as they are, without a second ``json_ready`` walk; a value that is not (a numpy
    scalar, a non-finite float) makes the encoder raise, and then the whole manifest is converted."""
    try:
        return dumps_compact(manifest, ready=True)
    except (TypeError, ValueError):
        return dumps_compact(manifest)


def remove_leftovers(out: Path) -> None:
    """Temporary files of an interrupted run (``.NAME.XXXX.tmp``), removed under the run's lock:
    no other run is writing outputs now (another run's write probe, made before it waits for the
    lock, may go too: that run does not need it back, pipeline/batch/run.py)."""
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


