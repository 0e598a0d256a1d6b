"""``trackproc batch``: a directory or glob of passes through ingest -> smooth (-> refine) (-> estimate), cron-grade.

The flags are generated from :data:`trackproc.pipeline.batch.schema.SCHEMA`, the same table that
defines the TOML keys and the ``TRACKPROC_BATCH_*`` environment variables, so the three can never
drift apart. Precedence: flag > environment > config file > default.
"""

from __future__ import annotations

import inspect
import logging
import sys
import time
from typing import List, Optional

import typer

from trackproc.cli.app import app
from trackproc.pipeline.batch.schema import CONFIG_ENV, SCHEMA

log = logging.getLogger("trackproc")

_PANELS = {"batch": "Run", "ingest": "Ingest step", "smooth": "Smooth step", "refine": "Refine step",
           "estimate": "Estimate step", "filter": "Filter step"}
_ANNOTATIONS = {"str": Optional[str], "path": Optional[str], "choice": Optional[str], "degree": Optional[str],
                "int": Optional[int], "float": Optional[float], "duration": Optional[str], "bool": Optional[bool],
                "list": Optional[List[str]], "paths": Optional[List[str]], "map": Optional[List[str]]}


def _help(opt) -> str:
    extra = f" One of: {', '.join(opt.choices)}." if opt.choices else ""
    return f"{opt.help}{extra} (config {opt.name}, env {opt.env})"


def batch_command(**kwargs) -> None:
    """Process many raw pass files through a chain of steps (ingest -> smooth, optionally refine of
    each pass, a multi-pass estimate per window and a sequential filter whose state is carried from
    run to run), in parallel, skipping results already up to date.

    Settings come from flags, TRACKPROC_BATCH_* environment variables and the TOML config file,
    in that order of precedence. Results go to OUTPUT/passes/ (one per input), OUTPUT/estimates/
    (one per window), OUTPUT/filter/ (state.json, the carried state, and one state per run),
    OUTPUT/summary.json, OUTPUT/summary.csv and
    OUTPUT/report.html (the results as a sortable table with figures, self-contained).

    Exit status: 0 all inputs (and windows) done, 3 some failed (each reported with its reason),
    1 all failed or another run holds the output directory, 2 usage error, 128 + N stopped by
    signal N (143 SIGTERM, 129 SIGHUP, 130 Ctrl-C) after stopping its workers: run it again to resume.

    Examples (run from the repository root, on the shipped sample_data/):

        trackproc batch sample_data/nightly.toml -o nightly-out

        trackproc batch --input 'sample_data/*.csv' --stations sample_data/stations.csv \\
            --carrier-hz 2.2e9 --mode one-way -o out --workers 2
    """
    config = kwargs.pop("config")
    flags = {opt.name: kwargs[opt.dest] for opt in SCHEMA}

    from trackproc.pipeline.batch.config import resolve

    settings = resolve(config, flags)
    handler, restore = _log_handler(settings.get("batch.log"))
    progress = _Progress(sys.stderr) if _show_progress() else None
    if progress is not None:
        handler.progress = progress
    try:
        from trackproc.pipeline.batch import Interrupted, run_batch, single_thread_blas

        if "numpy" not in sys.modules:  # one BLAS thread here too: --workers 1 computes as the workers do
            single_thread_blas()

        try:
            from trackproc.report.batch_html import write_report

            exit_code = run_batch(settings, progress=progress.update if progress else None,
                                  reporter=write_report).exit_code
        except Interrupted as exc:  # logged by run_batch; the shell's code for a death by that signal
            exit_code = exc.exit_code
    finally:
        if progress is not None:
            progress.finish()
        restore()
    raise typer.Exit(exit_code)


def _show_progress() -> bool:
    try:
        return sys.stderr.isatty() and logging.getLogger("trackproc").getEffectiveLevel() <= logging.INFO
    except (AttributeError, ValueError):
        return False


class _Handler(logging.StreamHandler):
    """Log lines with a UTC timestamp; clears the progress line before writing and redraws it after."""

    progress = None

    def emit(self, record):
        if self.progress is not None:
            self.progress.clear()
        super().emit(record)
        if self.progress is not None:
            self.progress.draw()


def _log_handler(path: Optional[str]):
    """Route the ``trackproc`` logger to stderr or ``--log FILE`` (appended) for this run."""
    logger = logging.getLogger("trackproc")
    saved = (list(logger.handlers), logger.propagate, logger.level)
    if path is not None:
        try:
            stream = open(path, "a", encoding="utf-8", buffering=1)
        except OSError as exc:
            from trackproc.errors import InputError

            raise InputError(f"cannot open the log file: {exc.strerror}", file=path, column="--log") from None
    else:
        stream = sys.stderr
    from trackproc.pipeline.batch.report import OneLineFilter

    handler = _Handler(stream)
    handler.addFilter(OneLineFilter())  # every record one line, whichever trackproc logger made it
    formatter = logging.Formatter("%(asctime)s trackproc batch[%(process)d]: %(levelname)s: %(message)s",
                                  "%Y-%m-%dT%H:%M:%SZ")
    formatter.converter = time.gmtime
    handler.setFormatter(formatter)
    root_level = logging.getLogger().getEffectiveLevel()
    logger.handlers[:] = [handler]
    logger.propagate = False
    logger.setLevel(root_level)

    def restore():
        handler.flush()
        if path is not None:
            stream.close()
        logger.handlers[:], logger.propagate, _ = saved
        logger.setLevel(saved[2])

    return handler, restore


class _Progress:
    """``\\r`` progress line on a terminal: done/total, failures, rate, a bar."""

    def __init__(self, stream):
        self.stream = stream
        self.t0 = time.monotonic()
        self.state = None
        self.shown = False

    def update(self, done: int, total: int, failed: int) -> None:
        self.state = (done, total, failed)
        self.draw()

    def _line(self) -> str:
        done, total, failed = self.state
        width = 30
        filled = int(width * done / total) if total else width
        rate = done / max(time.monotonic() - self.t0, 1e-9)
        return (f"[{'#' * filled}{'.' * (width - filled)}] {done}/{total} inputs, {failed} failed, "
                f"{rate:.1f}/s")

    def draw(self) -> None:
        if self.state is None:
            return
        self.stream.write("\r" + self._line() + "\033[K")
        self.stream.flush()
        self.shown = True

    def clear(self) -> None:
        if self.shown:
            self.stream.write("\r\033[K")
            self.stream.flush()

    def finish(self) -> None:
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


def _signature() -> inspect.Signature:
    params = [inspect.Parameter(
        "config", inspect.Parameter.KEYWORD_ONLY, annotation=Optional[str],
        default=typer.Argument(None, metavar="CONFIG.toml",
                               help=f"TOML config file (default: ${CONFIG_ENV}, else flags only)."))]
    for opt in SCHEMA:
        option = typer.Option(None, *opt.flags, help=_help(opt), metavar=opt.metavar,
                              rich_help_panel=_PANELS[opt.section], show_default=False)
        params.append(inspect.Parameter(opt.dest, inspect.Parameter.KEYWORD_ONLY, default=option,
                                        annotation=_ANNOTATIONS[opt.kind]))
    return inspect.Signature(params, return_annotation=None)


batch_command.__signature__ = _signature()
batch_command.__annotations__ = {p.name: p.annotation for p in batch_command.__signature__.parameters.values()}
batch_command.__annotations__["return"] = None
app.command("batch")(batch_command)
