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
# The user cache (parsed EOP/ICGEM tables, rendered --help) in a directory of this test process, not
# the user's ~/.cache: tests neither leave entries behind nor read a developer's.
if "TRACKPROC_CACHE_DIR" not in os.environ:
    import tempfile

    os.environ["TRACKPROC_CACHE_DIR"] = tempfile.mkdtemp(prefix="trackproc-test-cache-")

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


def _run_cli(args, input: bytes | str | None = None) -> CliResult:
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    try:
        with CliRunner().isolation(input=input) as (out, err, _):
            code = cli_app.main([str(a) for a in args])
            sys.stdout.flush()
            sys.stderr.flush()
            return CliResult(code, out.getvalue(), err.getvalue().decode("utf-8"))
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)


@pytest.fixture
def run_cli():
    """``run_cli(args, input=bytes)`` -> CliResult: the real entry point (``main``: exit codes and
    one-line errors) inside CliRunner's isolated stdin/stdout/stderr."""
    return _run_cli


@pytest.fixture(scope="session")
def run_cli_shared():
    """:func:`run_cli` for module- and session-scoped fixtures (one command's output that several
    tests check)."""
    return _run_cli


@pytest.fixture(scope="session")
def forked_trackproc(tmp_path_factory):
    """A directory to put first on PATH: its ``trackproc`` runs each command in a fork of one server
    that imported trackproc once (tests/cli/forkserver.py), for shell scripts whose subject is the
    commands, not the interpreter's start."""
    from forkserver import ForkServer

    directory = tmp_path_factory.mktemp("forkserver")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[1] / "src")] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    with ForkServer(directory, env) as bin_dir:
        yield bin_dir


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
# ``python -m pytest -m "not slow"`` is the fast tier (under a minute on 2 cores from a fresh clone,
# collection included: README); the whole suite is the default. A test is slow when it is statistical
# (Monte Carlo: many solves), reads the real data or runs a peer tool (markers ``realdata``/``validation``),
# is a subprocess/pipeline test that takes seconds, or costs seconds of CPU in-process (``SLOW_CPU``:
# among them every test that would compile the numba kernels on a fresh clone, ~10 s of CPU each set).
# The fast tier keeps at least one test of every layer folder and of every command.
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
    "test_hostile_signals.py": {"test_sigterm_of_a_running_command"},
    "test_startup.py": {"test_the_tour_does_not_import_scipy_optimize", "test_plain_command_runs_without_pydantic",
                        "test_commands_leave_numpys_unused_modules_unloaded_and_usable",
                        "test_help_from_the_cache_is_typers_without_typer"},
    "test_batch.py": {
        "test_dask_cluster_and_process_pool_give_the_serial_results", "test_a_dying_worker_fails_only_its_own_input",
        "test_a_killed_run_resumes_where_it_stopped", "test_two_overlapping_runs_do_not_corrupt_each_other",
        "test_changing_the_config_or_an_input_redoes_only_what_it_touches",
        "test_thirty_passes_five_broken_then_rerun_skips_then_force_redoes",
        "test_changing_a_refine_setting_redoes_only_the_refinements",
        "test_refine_step_writes_refined_states_and_fails_only_the_pass_it_cannot_refine",
        "test_estimate_windows_non_convergence_reported_then_redone_alone", "test_nightly_recipe",
        "test_progress_bar_only_on_a_terminal", "test_lock_blocks_a_second_run_or_makes_it_wait"},
}
#: Tests that cost seconds of CPU in one process, by module: a reason for the whole module (str), or
#: {test name (every parametrization) or name[id] (one): reason}. Seconds are the test's share of a
#: fast-tier run on the shared 2-core machine (load 3-4), before it moved here.
SLOW_CPU: dict[str, str | dict[str, str]] = {
    "test_taylor_jit.py": "compiles the numba Taylor kernels on a fresh clone (~10 s of CPU)",
    "test_batch_hostile.py": {
        "test_a_newline_in_a_file_name_cannot_forge_a_log_line": "batch estimate with the compiled kernels: "
                                                                 "compiles them on a fresh clone, 22-32 s"},
    "test_batch_report.py": {
        "test_report_lists_every_input_links_its_outputs_and_fetches_nothing": "a batch with the compiled kernels: "
                                                                               "compiles them on a fresh clone, 16 s "
                                                                               "(2.1 s warm)"},
    "test_batch_quality.py": {
        "test_the_summary_carries_each_solutions_verdict_and_strict_counts_suspect_as_failed":
            "batch refine with the compiled kernels (compiles them on a fresh clone), 2.2 s warm"},
    "test_forces_cli.py": {
        "test_passes_and_compare_take_full": "a full-force day: compiles the force kernels on a fresh clone, 35 s"},
    "test_hostile_formats.py": {
        "test_reentry_stops_with_its_time": "a full-force propagation to re-entry: compiles the force kernels on a "
                                            "fresh clone, 28 s"},
    "test_estimate_mismodel.py": {
        "test_unmodelled_drag_and_another_satellite_cover_or_say_so[drag_1]":
            "a day of full-force simulation: compiles the force kernels on a fresh clone, 37 s",
        "test_unmodelled_drag_and_another_satellite_cover_or_say_so[vhf_other_satellite]":
            "the leave-one-pass-out search of a failed estimate, 4.5-5.8 s",
        "test_a_long_dense_set_does_not_crash_the_noise_model": "12 h of 2 s samples simulated and estimated, 1.6 s"},
    "test_report_plots.py": {
        "test_smooth_figures_one_per_pass_png_and_pdf": "a PNG and a PDF figure per pass of the sample set, 12 s",
        "test_png_is_written": "a second smooth figure (test_smooth_cli.py test_plot_is_a_png stays fast), 1.1 s"},
    "test_passes.py": {
        "test_sample_state_passes_match_propagate_at_station": "two days of passes per station, each "
                                                               "propagated again at the station, 1.5-3.3 s each"},
    "test_ingest_stream.py": {
        "test_random_inputs_same_across_chunks": "12 random inputs, each ingested three times, 3.9 s in all"},
    "test_refine_mismodel.py": {
        "test_mismodelled_pass_is_covered_or_said[V55-twoway_as_oneway-cov]": "refine of a two-way pass, 1.0 s",
        "test_mismodelled_pass_is_covered_or_said[S55-thermal20-cov]": "refine of a 55 s S-band pass, 0.7 s",
        "test_mismodelled_pass_is_covered_or_said[V55-iono-cov]": "refine of a 55 s VHF pass, 0.6 s",
        "test_mismodelled_pass_is_covered_or_said[V55-sine5-nocov]": "refine of a 55 s VHF pass, 0.6 s"},
    "test_refine_noise.py": {
        "test_refine_with_wander_ar1_and_quantisation_is_honest_fast": "20 Monte Carlo refines (the 100-draw "
                                                                       "test beside it is slow too), 2.8 s",
        "test_effective_samples_of_an_ar1_process_is_its_closed_form": "a dense AR(1) covariance of 4000 "
                                                                       "samples, 1.7 s"},
    "test_hostile_outputs.py": {
        "test_unwritable_output_is_one_line[smooth-directory]": "smooth of the 14-pass sample set, 1.3 s",
        "test_unwritable_output_is_one_line[smooth-dev_full]": "smooth of the 14-pass sample set, 1.1 s",
        "test_unwritable_output_is_one_line[smooth-under_a_file]": "smooth of the 14-pass sample set, 0.9 s",
        "test_unwritable_output_is_one_line[smooth-deep_under_a_file]": "smooth of the 14-pass sample set, 0.7 s"},
    "test_two_way.py": {
        "test_cli_two_way_doppler_through_ingest_into_estimate": "simulate, ingest and a two-way estimate, 4.8 s"},
    "test_hostile_property.py": {
        "test_csv_reader_exit_0_or_one_line_exit_2": "hypothesis: 60 generated CSV inputs ingested, 3.7 s"},
    "test_smoothing.py": {
        "test_gls_covariance_covers_ar1_noise_where_the_white_one_does_not": "300 draws fitted twice (GLS, "
                                                                             "white), 1.3 s",
        "test_simulated_doppler_passes_with_correlated_and_quantised_noise": "12 simulated passes smoothed per "
                                                                             "noise kind, 0.2-0.6 s each"},
    "test_refine.py": {
        "test_circular_consistency_flags_a_pass_that_contradicts_the_constraints": "four constrained refines, "
                                                                                    "1.6 s"},
    "test_smooth_cli.py": {
        "test_multistation_sample_is_smoothed_to_its_noise_free_truth_without_discarding_good_data":
            "smooth of the 14-pass sample set against its truth, 2.0 s"},
    "test_accuracy_cli.py": {
        "test_seed_example_table_and_plot": "the seed 000 example table and its figure, 2.4 s"},
    "test_hostile_resources.py": {
        "test_hostile_sidecar[<lambda>-needles16]": "a YAML sidecar nested 5000 deep, 1.8 s"},
    "test_filter.py": {
        "test_zero_process_noise_iterated_smoother_equals_estimate": "an iterated smoother and an estimate, 1.0 s",
        "test_unmodelled_manoeuvre_diverges_without_process_noise_and_not_with_snc": "two filter runs, 0.7 s"},
    "test_tle_fit_conflict.py": {
        "test_conflict_statistic_is_chi2_7_monte_carlo": "Monte Carlo of the conflict statistic, 1.1 s"},
    "test_fit_tle_apriori.py": {
        "test_a_time_tag_shift_within_the_theory_error_is_not_a_conflict": "two TLE fits, 0.7 s"},
    "test_filter_reference.py": {
        "test_a_restarted_trajectory_sees_the_absolute_time_of_the_sun_and_the_moon": "full-force restarts: "
                                                                                      "compiles the force kernels "
                                                                                      "on a fresh clone",
        "test_the_propagated_span_grows_with_the_arc_not_its_square": "filters over 1 and 4 days, 1.1 s",
        "test_a_full_force_reference_restarts_at_each_segment_and_stays_the_epochs_trajectory":
            "a 2-day full-force sweep: compiles the force kernels on a fresh clone",
        "test_the_full_models_steps_meet_without_a_jump": "full-force run: compiles the force kernels on a "
                                                          "fresh clone"},
    "test_forces_native.py": {
        "test_undefined_symbols_match_nm": "stores the machine code when none is: compiles the force kernels on a "
                                           "fresh clone"},
    "test_progress.py": {
        "test_pipe_quiet_short_and_batch_see_nothing": "sleeps 1.25 s past the progress line's timers "
                                                       "(test_terminal_sees_progress_then_a_clean_line stays)"},
}


def _slow_reason(module: str, name: str, item_name: str) -> str | None:
    """Why ``SLOW_CPU`` puts this test in the slow tier (None when it does not)."""
    entry = SLOW_CPU.get(module)
    if entry is None or isinstance(entry, str):
        return entry
    return entry.get(item_name) or entry.get(name)


def _warn_missing_slow_names(config, items) -> None:
    """A renamed test (or parametrization) would drop out of the slow tier silently: say so."""
    modules = {item.path.name: getattr(item, "module", None) for item in items}
    ids = {(item.path.name, item.name) for item in items}
    functions = {(item.path.name, getattr(item, "originalname", item.name)) for item in items}
    tables = {"SLOW_SUBPROCESS": {m: names for m, names in SLOW_SUBPROCESS.items() if names is not None},
              "SLOW_CPU": {m: set(entry) for m, entry in SLOW_CPU.items() if not isinstance(entry, str)}}
    for table, entries in tables.items():
        for module, names in entries.items():
            if module not in modules:
                continue
            missing = []
            for name in sorted(names):
                function, _, param = name.partition("[")
                source = modules[module]
                if source is not None and not callable(getattr(source, function, None)):
                    missing.append(name)          # the function is gone
                elif param and (module, function) in functions and (module, name) not in ids:
                    missing.append(name)          # its parametrizations are collected, this one is not
            if missing:
                config.issue_config_time_warning(pytest.PytestConfigWarning(
                    f"tests/conftest.py {table} names tests not in {module}: {', '.join(missing)}"), stacklevel=2)
    whole = {m for m, names in SLOW_SUBPROCESS.items() if names is None} | set(SLOW_CPU)
    existing = {path.name for path in TESTS.rglob("test_*.py")}
    gone = sorted(whole - existing)
    if gone:
        config.issue_config_time_warning(pytest.PytestConfigWarning(
            f"tests/conftest.py names test modules that do not exist: {', '.join(gone)}"), stacklevel=2)


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
        if (reasons or _slow_reason(module, name, item.name) or item.get_closest_marker("realdata")
                or item.get_closest_marker("validation")):
            for mark in reasons:
                item.add_marker(mark)
            item.add_marker(pytest.mark.slow)
    _warn_missing_slow_names(config, items)
    # The slow tier first (a stable sort: each tier keeps the files' order, the same in every xdist
    # worker): with pytest-xdist's work stealing (pyproject.toml's addopts) a worker that runs out takes
    # the other's remaining tests, so the run ends on short tests instead of one worker finishing a
    # long Monte Carlo while the other waits.
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
