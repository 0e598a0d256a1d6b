"""Shared fixtures: run the ``trackproc`` CLI in-process, write small input files; the ``slow`` tier."""

from __future__ import annotations

import logging
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

# One BLAS thread per test process (unless set by the caller): the matrices here are small, and with
# -n 2 on 2 cores OpenBLAS's own threads oversubscribe the cores and spin (tests/pipeline/test_smoothing.py with
# -n 2 on a loaded machine: 104 s wall, 31.5 s CPU with 2 threads; 22 s, 5.4 s with 1). Set before numpy
# is first imported; the results are unchanged (tests/test_golden.py passes either way).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402
from typer.testing import CliRunner  # noqa: E402

from trackproc.cli import app as cli_app  # noqa: E402

cli_app._register()

STATIONS_CSV = "station,lat_deg,lon_deg,height_m\nZHY,40.0,116.0,50\nKIR,67.8,20.9,400\n"


@dataclass
class CliResult:
    exit_code: int
    stdout_bytes: bytes
    stderr: str

    @property
    def stdout(self) -> str:
        return self.stdout_bytes.decode("utf-8")


@pytest.fixture
def run_cli():
    """``run_cli(args, input=bytes)`` -> CliResult: the real entry point (``main``: exit codes and
    one-line errors) inside CliRunner's isolated stdin/stdout/stderr."""
    runner = CliRunner()

    def run(args, input: bytes | str | None = None) -> CliResult:
        root = logging.getLogger()
        handlers, level = list(root.handlers), root.level
        try:
            with runner.isolation(input=input) as (out, err, _):
                code = cli_app.main([str(a) for a in args])
                sys.stdout.flush()
                sys.stderr.flush()
                return CliResult(code, out.getvalue(), err.getvalue().decode("utf-8"))
        finally:
            root.handlers[:] = handlers
            root.setLevel(level)

    return run


@pytest.fixture
def write(tmp_path: Path):
    """``write(name, text_or_bytes)`` -> path of a new file in ``tmp_path``."""

    def make(name: str, content: str | bytes) -> Path:
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content.encode("utf-8") if isinstance(content, str) else content)
        return path

    return make


@pytest.fixture
def stations_csv(write) -> Path:
    """Stations ZHY (40 N, 116 E, 50 m) and KIR (67.8 N, 20.9 E, 400 m)."""
    return write("stations.csv", STATIONS_CSV)


# --- the slow tier ----------------------------------------------------------------------------------
# ``python -m pytest -m "not slow"`` is the fast tier (under a minute on 2 cores); the whole suite is the
# default. A test is slow when it is statistical (Monte Carlo: many solves), reads the real data or runs
# a peer tool (markers ``realdata``/``validation``), or is a subprocess/pipeline test that takes seconds.
# Assigned here, by module and name, so that test files need no marker lines.

#: Monte Carlo and other statistical tests, by name.
STATISTICAL = re.compile(r"by_monte_carlo|monte_carlo_(nees|error_rates|within|agrees|beats|decisions)|_draws|"
                         r"chi2_band|chi2_2|calibrated|scatter|noise_statistics|"
                         r"^test_simulated_doppler_from_trackproc_simulate_fitted_to_the_noise_level$")
#: Tests that run trackproc (or bash) in subprocesses, or process pools and clusters, for seconds.
SLOW_SUBPROCESS = {
    "test_cli_recipes.py": None,                                   # None: the whole module
    "test_ingest.py": {"test_real_pipe_ingest_to_info", "test_real_pipe_closed_early_is_quiet"},
    "test_smooth_cli.py": {"test_real_pipe_ingest_to_smooth",
                           "test_real_pipe_simulate_to_smooth_every_kind_at_the_noise_level"},
    "test_estimate_cli.py": {"test_real_pipe_simulate_into_estimate"},
    "test_simulate.py": {"test_subprocess_pipe_into_ingest_and_info"},
    "test_propagate_cli.py": {"test_subprocess_pipe_arrow_stream"},
    "test_accuracy_cli.py": {"test_real_pipe"},
    "test_cli_basics.py": {"test_reader_closing_the_pipe_early_ends_quietly_with_141"},
    "test_batch_hostile.py": {"test_sigterm_while_waiting_for_the_lock_or_working_alone",
                              "test_sigterm_stops_the_pool_and_the_next_run_resumes",
                              "test_sigkill_of_the_driver_ends_its_workers"},
    "test_hostile_time.py": {"test_parquet_year_3000_never_aborts"},
    "test_batch.py": {
        "test_dask_cluster_and_process_pool_give_the_serial_results", "test_a_dying_worker_fails_only_its_own_input",
        "test_a_killed_run_resumes_where_it_stopped", "test_two_overlapping_runs_do_not_corrupt_each_other",
        "test_changing_the_config_or_an_input_redoes_only_what_it_touches",
        "test_thirty_passes_five_broken_then_rerun_skips_then_force_redoes",
        "test_changing_a_refine_setting_redoes_only_the_refinements",
        "test_refine_step_writes_refined_states_and_fails_only_the_pass_it_cannot_refine",
        "test_estimate_windows_non_convergence_reported_then_redone_alone", "test_nightly_recipe",
        "test_progress_bar_only_on_a_terminal"},
}


# --- the layers -------------------------------------------------------------------------------------
# The test folders mirror the layers of src/trackproc (pyproject.toml [tool.importlinter]): a test file
# sits in tests/<layer>/ for the highest layer it exercises (the CLI when it runs commands), and is marked
# ``layer_<layer>`` from its folder: ``pytest -m layer_dynamics`` (or ``pytest tests/dynamics``) runs the
# bottom layer's tests. tests/test_layers.py checks that each file's imports agree with its folder. The
# root keeps the whole-package checks (layer contract, golden outputs), the leaf modules' tests
# (isotime) and the helpers shared by several folders (realdata.py, hostile.py, orekit_*.py, ...), which
# are importable from every folder (pyproject ``pythonpath``), as are the test modules themselves.
LAYERS = ("cli", "report", "pipeline", "io", "types", "methods", "models", "dynamics")
TESTS = Path(__file__).resolve().parent


def layer_of(path: Path) -> str | None:
    """The layer folder a test file sits in (None at the root)."""
    folder = path.resolve().parent
    return folder.name if folder.parent == TESTS and folder.name in LAYERS else None


def pytest_collection_modifyitems(config, items):
    for item in items:
        layer = layer_of(item.path)
        if layer:
            item.add_marker(getattr(pytest.mark, f"layer_{layer}"))
        module = item.path.name
        name = getattr(item, "originalname", item.name)
        reasons = []
        if STATISTICAL.search(name):
            reasons.append(pytest.mark.statistical)
        names = SLOW_SUBPROCESS.get(module, ())
        if names is None or name in names:
            reasons.append(pytest.mark.subprocess)
        if reasons or item.get_closest_marker("realdata") or item.get_closest_marker("validation"):
            for mark in reasons:
                item.add_marker(mark)
            item.add_marker(pytest.mark.slow)
    # a renamed test would drop out of the slow tier silently: say so
    seen = {(item.path.name, getattr(item, "originalname", item.name)) for item in items}
    modules = {module for module, _ in seen}
    for module, names in SLOW_SUBPROCESS.items():
        missing = sorted(n for n in names or () if module in modules and (module, n) not in seen)
        if missing:
            config.issue_config_time_warning(pytest.PytestConfigWarning(
                f"tests/conftest.py SLOW_SUBPROCESS names tests not in {module}: {', '.join(missing)}"), stacklevel=2)
