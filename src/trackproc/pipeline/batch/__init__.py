"""``trackproc batch``: many passes through a chain of steps, in parallel, resumable, cron-grade.

The chain is a list of named steps (:data:`CHAIN`: ingest, smooth, refine, estimate, filter). Each step
is a small adapter (:class:`Step`) around one pipeline function:

- ``scope="input"`` steps run once per input file, in order, on an :class:`InputContext`
  (``ctx.table`` is the pass table handed from step to step; a step adds its side outputs and
  its key numbers). When the chain does not start with ``ingest`` the inputs are read as
  canonical pass files. ``ingest`` and ``smooth`` make the table (``Step.table``); ``refine``
  only reads it (the stale state refined from the input's pass, ``<name>.refined.json``; the
  pass with the most samples when an input holds several, :func:`refine_pass`).
- ``scope="window"`` steps run once per window of processed inputs (``estimate``: one orbit
  from all the passes of a window, ``[estimate] window_s``) on a :class:`WindowContext`.

Adding a step is an adapter in :mod:`.steps` and one :func:`register` call, plus its settings
section in :mod:`.schema` (the schema gives the TOML keys, the flags and the environment
variables). The position in :data:`CHAIN` fixes where it runs.

Work and results (``OUTPUT`` is the output directory):

- ``OUTPUT/passes/<name>.parquet`` (the last table of the chain), the side outputs of each step
  (``<name>.smooth.json``, ``<name>.refined.json``), and ``<name>.batch.json``: the manifest —
  the content key, the status, the key numbers, the error and the outputs with their sizes and
  SHA-256. ``<name>``
  is the input's path relative to its directory (or to the fixed part of its glob), without
  the suffix, so sub-directories are mirrored.
- ``OUTPUT/estimates/<window>.json`` (state file), ``<window>.residuals.parquet``, manifest.
- ``OUTPUT/filter/state.json``: the ``filter`` step's carried state (``scope="sequence"``: one
  run over every processed input in the driver, continuing the previous run's state), and
  ``OUTPUT/filter/<last measurement>.json`` per run.
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
failed; usage errors raise :class:`~trackproc.errors.InputError` (2) before any work; SIGTERM,
SIGHUP or SIGINT stop the workers and raise :class:`Interrupted` (the CLI exits 128 + the
signal number, 143 for SIGTERM); the next run resumes.

The modules, by responsibility:

- :mod:`.schema`, :mod:`.config`: the settings (one table for TOML keys, flags, variables) and
  their resolution;
- :mod:`.chain`: the step registry and the configured chain; :mod:`.steps`: the step adapters;
- :mod:`.tasks`: a unit of work and :func:`run_task`, run in any process;
- :mod:`.executors`: this process, a process pool, a Dask cluster; the pool's clean shut-down
  on SIGTERM and its workers' exit when the run dies;
- :mod:`.discovery`: input files and their result names; :mod:`.lock`: the output directory's lock;
- :mod:`.store`: content keys, records, manifests; :mod:`.report`: log lines and summary files;
- :mod:`.run`: :func:`run_batch`.

The names below are imported from their modules when first used (:pep:`562`): the CLI imports
:mod:`.schema` at start-up for ``trackproc batch --help``, which needs none of the rest.
"""

from __future__ import annotations

import importlib

#: module -> the public names this package re-exports from it
EXPORTS = {
    "chain": ("CHAIN", "STEPS", "Step", "register", "make_chain", "Chain", "InputContext", "WindowContext"),
    "steps": ("refine_pass", "REFINE_PASS_RULE", "ingest_step", "smooth_step", "refine_step", "estimate_step",
              "filter_step"),
    "tasks": ("Task", "TaskResult", "run_task"),
    "executors": ("Interrupted", "interruptible", "SerialExecutor", "PoolExecutor", "DaskExecutor", "execute",
                  "single_thread_blas", "BLAS_THREAD_VARIABLES"),
    "discovery": ("discover", "InputFile"),
    "lock": ("batch_lock", "LockedError", "LOCK_NAME"),
    "store": ("Record", "CSV_COLUMNS", "PASSES_DIR", "ESTIMATES_DIR", "MANIFEST_SUFFIX"),
    "report": ("BatchResult", "summary_csv", "printable", "SUMMARY_JSON", "SUMMARY_CSV"),
    "run": ("run_batch", "window_of"),
    "schema": ("SCHEMA", "documentation_table"),
    "config": ("Settings", "resolve"),
}
_MODULE_OF = {name: module for module, names in EXPORTS.items() for name in names}

__all__ = sorted(_MODULE_OF)


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    importlib.import_module(f"{__name__}.steps")  # the registry is only complete with its steps registered
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(__all__))
