"""``trackproc batch``: the run: inputs, then windows, under the output directory's lock.

See :mod:`trackproc.pipeline.batch` for what a run does and leaves behind. About 400 lines, one
responsibility (the run's order: inputs, windows, the filter, the summary), the steps and the
storage being their own modules.
"""

from __future__ import annotations

import calendar
import contextlib
import json
import logging
import math
import os
import time
from pathlib import Path
from typing import Callable, Optional

from trackproc import __version__
from trackproc.errors import InputError, OutputError, ProcessingError, TrackprocError
from trackproc.io.atomic import max_input_bytes, write_bytes
from trackproc.io.jsonutil import json_ready
from trackproc.io.statecheck import certainly_valid
from trackproc.pipeline.batch.chain import STEPS, Chain, WindowContext, make_chain
from trackproc.pipeline.batch.config import Settings
from trackproc.pipeline.batch.discovery import discover
from trackproc.pipeline.batch.executors import Executors, Interrupted, execute, interruptible
from trackproc.pipeline.batch.lock import batch_lock
from trackproc.pipeline.batch.report import BatchResult, finish, log_record
from trackproc.pipeline.batch.steps import initial_state
from trackproc.pipeline.batch.store import (ESTIMATES_DIR, PASSES_DIR, Record, content_key, manifest_path,
                                            read_manifest, record_from_manifest, remove_leftovers, sha256,
                                            step_options, store_result, stored_stage, up_to_date, utc_now)
from trackproc.pipeline.batch.tasks import Task, TaskResult

log = logging.getLogger("trackproc.batch")


def run_batch(settings: Settings, progress: Optional[Callable] = None,
              reporter: Optional[Callable] = None) -> BatchResult:
    """Run the configured batch (see the module docstring); ``progress(done, total, failed)``
    is called as tasks finish; ``reporter(out, summary)`` writes further pages from the summary
    (the CLI's report.html), under the lock, after the summary files. Raises :class:`InputError` for usage errors before any work,
    :class:`LockedError` when another run holds the output directory and
    :class:`~trackproc.pipeline.batch.executors.Interrupted` when a signal (SIGTERM, SIGHUP,
    SIGINT) stopped the run, after stopping its workers."""
    started, t0 = utc_now(), time.perf_counter()
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
    if "filter" in chain.names and not settings.get("filter.initial"):
        raise InputError("the filter step needs an initial state", column="--filter-initial",
                         expected="--filter-initial STATE.json|TLE, or initial = \"...\" in [filter]")
    if "filter" in chain.names and settings.get("filter.eop") is not None and settings.get("filter.dut1") is not None:
        raise InputError("give either an EOP file or UT1-UTC, not both", column="filter.eop / filter.dut1",
                         expected="one of --filter-eop, --filter-dut1")
    files, paths, hashes = _read_files(settings, chain)
    if "refine" in chain.names and not certainly_valid(files["refine.initial"]):
        # a state file every input would fail on: a usage error, now (the reader's own error; a
        # file certainly valid is not parsed here: a pool's driver then never imports numpy)
        initial_state(files["refine.initial"], paths["refine.initial"], None)
    out = Path(output)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".write-test-{os.getpid()}.tmp"      # a read-only file system or a full disk: now
        probe.write_bytes(b"")
        # a run holding the lock may have removed it already as a leftover (remove_leftovers: this
        # probe is written before the lock is taken)
        probe.unlink(missing_ok=True)
    except OSError as exc:
        raise OutputError(output, exc) from None
    try:
        with interruptible(), batch_lock(out, settings.get("batch.wait"), settings.get("batch.wait_timeout_s")):
            remove_leftovers(out)
            inputs = discover(entries, settings.get("batch.patterns"),
                              exclude=[output] + [p for p in paths.values() if p])
            executors = Executors(settings)
            try:
                records = _run_inputs(settings, chain, inputs, files, paths, hashes, out, executors, progress)
                windows = (_run_windows(settings, chain, records, files, paths, hashes, out, executors)
                           if chain.window_steps else [])
                if chain.sequence_steps:
                    windows = windows + _run_filter(settings, records, files, paths, out)
            except BaseException:  # a signal, a bug: no worker may outlive the run
                executors.abort()
                raise
            executors.close()
            return finish(settings, chain, records, windows, out, started, t0, executors.label, reporter)
    except Interrupted as exc:
        log.error("%s: no worker left running; the results finished so far are kept and the next run resumes "
                  "from them (exit %d)", exc, exc.exit_code)
        raise


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
    for name in sorted(set(chain.files("input")) | set(chain.files("window")) | set(chain.files("sequence"))):
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
        table_key = content_key({**base, "input_sha256": sha256(data)})
        return (table_key if side is None else content_key({**side, "table_key": table_key})), table_key

    return keys


def _read_input(item):
    """``(bytes, None, None)`` of an input, or ``(None, error, error_type)``: a name that is not
    UTF-8 or a file above the input bound (``TRACKPROC_MAX_INPUT_MB``, checked on its size
    before reading) is an input error of that input alone; an unreadable file an internal one."""
    if item.problem:
        return None, f"{item.path}: {item.problem}", "input"
    try:
        size, limit = os.stat(item.path).st_size, max_input_bytes()
        if size > limit:
            return None, (f"{item.path}: input larger than the limit of {limit / (1 << 20):g} MiB "
                          f"({size} bytes); expected a smaller input, or a larger "
                          "TRACKPROC_MAX_INPUT_MB"), "input"
        return Path(item.path).read_bytes(), None, None
    except OSError as exc:
        return None, f"{item.path}: cannot read: {exc.strerror}", "internal"


def _run_inputs(settings, chain, inputs, files, paths, hashes, out, executors, progress):
    input_files = {k: hashes[k] for k in chain.files("input")}
    options_doc = step_options(settings, chain.input_steps, input_files)
    keys = _input_keys(settings, chain, hashes)
    force, retry = settings.get("batch.force"), settings.get("batch.retry_failed")
    records: dict = {}
    todo = []
    manifests = {}
    for item in inputs:
        data, error, error_type = _read_input(item)
        if data is None:
            records[item.name] = Record(task="pass", name=item.name, status="failed", skipped=False, key="",
                                        path=item.path, error=error, error_type=error_type)
            log.error("%s: failed: %s", item.path, error)
            continue
        key, table_key = keys(data)
        manifest = read_manifest(manifest_path(out, PASSES_DIR, item.name))
        manifests[item.name] = manifest
        if not force and up_to_date(manifest, key, out, retry):
            records[item.name] = record_from_manifest(manifest, "pass")
            continue
        stage = None if force or not chain.side_steps else stored_stage(manifest, table_key, out)
        todo.append((item, key, table_key, stage))
    total = len(inputs)
    n_skipped = len(records)
    n_side = sum(stage is not None for *_, stage in todo)
    n_unread = sum(r.status == "failed" and not r.key for r in records.values())
    log.info("%d input(s): %d up to date, %d to do (steps %s%s)%s", total, n_skipped - n_unread, len(todo),
             " -> ".join(chain.names), f"; {n_side} of them {', '.join(chain.side_steps)} only, from their stored "
                                        f"{' and '.join(chain.table_steps) or 'pass'} results" if n_side else "",
             f"; {n_unread} refused before reading" if n_unread else "")
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
                                side_steps=chain.side_steps, stage=stage, table_key=table_key, jit=executors.jit)
        data, error, error_type = _read_input(item)
        if data is None:
            records[item.name] = Record(task="pass", name=item.name, status="failed", skipped=False, key=key,
                                        path=item.path, error=error, error_type=error_type)
            log_record(records[item.name])
            done[0] += 1
            done[1] += 1
            return None
        key, table_key = keys(data)  # the bytes sent are the bytes hashed
        return Task(kind="input", name=item.name, key=key, steps=chain.table_steps, options=options,
                    files=task_files, paths=task_paths, source=item.path, data=data, reads_raw=chain.reads_raw,
                    side_steps=chain.side_steps, table_key=table_key, jit=executors.jit)

    settings_doc = json_ready({"steps": list(chain.input_steps), **options_doc})  # once: each manifest holds it

    def on_result(entry, result: TaskResult):
        item = entry[0]
        record = store_result(out, PASSES_DIR, result, task="pass", path=item.path, old=manifests.get(item.name),
                              settings_doc=settings_doc)
        records[item.name] = record
        log_record(record, result)
        done[0] += 1
        done[1] += record.status == "failed"
        if progress:
            progress(done[0], total, done[1])

    if todo:
        execute(executors.get(len(todo)), todo, make_task, on_result)
    return [records[n] for n in sorted(records)]


def window_of(start_utc: str, window_s: float) -> tuple:
    """(name, start) of the window holding ``start_utc``: windows of ``window_s`` seconds aligned
    on 1970-01-01T00:00:00Z (86400: UTC days, named YYYY-MM-DD); ``window_s = 0``: ``all``."""
    if not window_s:
        return "all", None
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
        key = content_key({"trackproc": __version__, "steps": list(chain.window_steps), **options_doc,
                    "members": member_keys})
        manifest = read_manifest(manifest_path(out, ESTIMATES_DIR, name))
        manifests[name] = manifest
        if len(members) < min_inputs:
            results[name] = Record(task="estimate", name=name, status="failed", skipped=False, key=key,
                                   error=f"{len(members)} processed input(s) in the window; at least {min_inputs} "
                                         "needed (estimate.min_inputs)", error_type="processing",
                                   members=[r.name for r in members])
            log_record(results[name])
            continue
        if not force and up_to_date(manifest, key, out, retry):
            results[name] = record_from_manifest(manifest, "estimate")
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
                    paths=task_paths, members=data, jit=executors.jit)

    settings_doc = json_ready({"steps": list(chain.window_steps), **options_doc})

    def on_result(entry, result: TaskResult):
        name, key, members = entry
        record = store_result(out, ESTIMATES_DIR, result, task="estimate", path=None, old=manifests.get(name),
                              settings_doc=settings_doc, members=[r.name for r in members])
        results[name] = record
        log_record(record, result)

    execute(executors.get(len(todo)), todo, make_task, on_result)
    return [results[n] for n in sorted(results)]


FILTER_DIR = "filter"


def filter_state_path(settings: Settings, out: Path) -> Path:
    """Where the filter step keeps its carried state: ``filter.state``, else ``OUTPUT/filter/state.json``."""
    return Path(settings.get("filter.state") or out / FILTER_DIR / "state.json")


def _run_filter(settings, records, files, paths, out) -> list:
    """The filter step, in this process (each run continues the previous one's state): every
    processed input's pass table, from the carried state when it exists (else ``filter.initial``).
    Writes ``OUTPUT/filter/<last measurement>.json`` then the carried state (each atomically);
    nothing newer than the carried state: nothing done, the record says up to date."""
    state_path = filter_state_path(settings, out)
    members = [r for r in records if r.status == "ok"]
    run_files, run_paths = dict(files), dict(paths)
    carried = None
    if state_path.exists():
        carried = state_path.read_bytes()
        run_files["filter.carried"], run_paths["filter.carried"] = carried, str(state_path)
        last = (json_loads(carried).get("filter") or {}).get("last_measurement")
        ends = [_utc(r.numbers.get("end_utc")) for r in members]
        newest = max((e for e in ends if e is not None), default=None)
        if last and newest is not None and _utc(last) is not None and newest <= _utc(last):
            record = Record(task="filter", name="filter", status="ok", skipped=True, key="", path=str(state_path),
                            numbers={"end_utc": last},
                            warnings=[f"no pass newer than the carried state's last measurement {last}"])
            log.info("filter: no pass newer than the carried state's last measurement %s: %s kept", last, state_path)
            return [record]
    data = [(f"{PASSES_DIR}/{r.name}.parquet", (out / PASSES_DIR / f"{r.name}.parquet").read_bytes())
            for r in members]
    ctx = WindowContext(name="filter", members=data, files=run_files, paths=run_paths)
    t0 = time.perf_counter()
    try:
        if not data:
            raise ProcessingError("no processed input to filter")
        STEPS["filter"].run(ctx, settings.section("filter"))
    except TrackprocError as exc:
        record = Record(task="filter", name="filter", status="failed", skipped=False, key="", path=str(state_path),
                        error=f"filter: {exc}", error_type="processing", members=[r.name for r in members])
        log.error("filter: failed: %s (the carried state %s is unchanged)", exc, state_path)
        return [record]
    name = ctx.numbers["end_utc"].replace(":", "").replace("-", "")
    dated = out / FILTER_DIR / f"{name}.json"
    write_bytes(dated, ctx.outputs[".json"])
    write_bytes(state_path, ctx.outputs[".json"])
    log.info("filter: %d samples (%d edited) up to %s, %s -> %s and %s", ctx.numbers["samples"],
             ctx.numbers["edited"], ctx.numbers["end_utc"], "from the carried state" if carried else
             "from " + str(paths.get("filter.initial")), dated, state_path)
    return [Record(task="filter", name=name, status="ok", skipped=False, key="", path=str(state_path),
                   numbers=ctx.numbers, details=ctx.details, warnings=ctx.warnings,
                   outputs=[str(dated.relative_to(out)) if dated.is_relative_to(out) else str(dated), str(state_path)],
                   seconds=round(time.perf_counter() - t0, 3), members=[r.name for r in members])]


def _utc(text):
    """An ISO UTC time as numpy datetime64 (ns), or None."""
    import numpy as np  # numpy after the driver fixed the BLAS threads (batch/steps)

    try:
        return np.datetime64(str(text).rstrip("Z"), "ns") if text else None
    except ValueError:
        return None


def json_loads(data: bytes) -> dict:
    try:
        doc = json.loads(data)
    except ValueError:
        return {}
    return doc if isinstance(doc, dict) else {}
