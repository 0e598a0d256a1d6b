"""Tasks of ``trackproc batch``: self-contained units of work and the function that runs one, in any process.

Every task is a pure function of its payload (input bytes, settings, file contents) and the
driver alone writes files, so every way of running (this process, a pool, a Dask cluster) gives
the same bytes. The pass-file reader (pandas, pyarrow) is imported where a task needs it, as
the steps' modules are (see :mod:`.steps`).
"""

from __future__ import annotations

import logging
import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Optional

import trackproc.pipeline.batch.steps  # noqa: F401 - registers the steps (a worker unpickling run_task needs them)
from trackproc.dynamics import jit
from trackproc.errors import InputError, TrackprocError
from trackproc.io.jsonutil import json_ready
from trackproc.pipeline.batch.chain import STEPS, InputContext, WindowContext

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
    #: run under ``TRACKPROC_JIT=1`` unless the environment says otherwise
    #: (:func:`trackproc.pipeline.batch.kernels.compiled_kernels`)
    jit: bool = False


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
    with jit.default("1" if task.jit else ""):
        return _run_task(task)


def _run_task(task: Task) -> TaskResult:
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
                from trackproc.io.passfile import parse_pass_table  # start-up: pandas, pyarrow (batch/steps)

                ctx.table = parse_pass_table(task.data, task.source)
            if task.stage is not None:  # the table stage is stored: only the side steps run
                stage = task.stage
                ctx.numbers = dict(stage["numbers"])
                ctx.details = dict(stage["details"])
                ctx.warnings = list(stage["warnings"])
            else:
                for name in task.steps:
                    STEPS[name].run(ctx, task.options[name])
                from trackproc.io.passfile import pass_table_bytes  # start-up: pandas, pyarrow (batch/steps)

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
    from trackproc.isotime import iso_utc           # numpy: not in a pool's driver, which runs no task

    times = table.column("time")                    # numpy columns: pandas calls cost ~3 ms a pass
    stations = table.column("station")
    passes = table.column("pass_id")
    n = table.n_rows
    return {"samples": int(n), "passes": len(set(zip(stations.tolist(), passes.tolist()))),
            "stations": " ".join(sorted(set(stations.tolist()))),
            "kinds": " ".join(sorted(set(table.column("kind").tolist()))),
            "start_utc": iso_utc(times.min(), 6) if n else None,
            "end_utc": iso_utc(times.max(), 6) if n else None}


