"""Start-up path (issue 19): ``trackproc COMMAND --help`` imports neither pydantic nor the numeric
stack, and typer's own coercion still runs for values that need converting."""

import subprocess
import sys

import pytest

from trackproc.cli.app import main

HEAVY = ("pydantic", "numpy", "scipy", "pandas", "pyarrow")


@pytest.mark.subprocess
@pytest.mark.parametrize("command", ["refine", "estimate", "batch", "ingest"])
def test_command_help_imports_nothing_heavy(command):
    probe = ("import io, sys; from trackproc.cli import app as a; out = sys.stdout; "
             f"sys.stdout = io.StringIO(); code = a._main([{command!r}, '--help']); "
             "text = sys.stdout.getvalue(); sys.stdout = out; "
             f"print(code, 'Usage:' in text, *[m for m in {HEAVY!r} if m in sys.modules])")
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["0", "True"], res.stdout + res.stderr


def test_values_still_validated_by_typer(capsys):
    # a float below its minimum and a non-number: typer's (pydantic) coercion, exit 2, one line
    assert main(["refine", "p.csv", "--initial", "s.json", "--circular-tolerance", "-1"]) == 2
    err = capsys.readouterr().err
    assert "--circular-tolerance" in err and "greater than or equal to 0" in err
    assert main(["refine", "p.csv", "--initial", "s.json", "--max-iterations", "abc"]) == 2
    assert "valid integer" in capsys.readouterr().err


@pytest.mark.subprocess
def test_plain_command_runs_without_pydantic(tmp_path):
    # strings, an enum given by value, a plain float: no pydantic import, same output as typer's
    args = ["-q", "ingest", "sample_data/doppler_pass.csv", "--stations", "sample_data/stations.csv",
            "--carrier-hz", "2.2e9", "--mode", "one-way", "-o"]
    probe = ("import sys; from trackproc.cli import app as a, coercion as c; {patch}"
             "code = a._main({args!r} + [sys.argv[1]]); print(code, 'pydantic' in sys.modules)")
    root = __import__("pathlib").Path(__file__).resolve().parents[2]
    fast = subprocess.run([sys.executable, "-c", probe.format(patch="", args=args), str(tmp_path / "a.parquet")],
                          capture_output=True, text=True, check=True, cwd=root)
    slow = subprocess.run([sys.executable, "-c", probe.format(
        patch="c.plain_value = lambda d, v: c.NOT_PLAIN; c.plain_default = lambda p, v, x: False; ", args=args),
        str(tmp_path / "b.parquet")], capture_output=True, text=True, check=True, cwd=root)
    assert fast.stdout.split() == ["0", "False"], fast.stdout + fast.stderr
    assert slow.stdout.split() == ["0", "True"], slow.stdout + slow.stderr
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()


def test_plain_values_equal_typers_own_coercion():
    """Every value the light path converts is what typer's pydantic coercion gives for it."""
    import enum
    from typing import List, Optional

    from typer import _coercion
    from typer.models import OptionInfo

    from trackproc.cli import coercion as a

    class Colour(enum.Enum):
        red = "red"
        dark_red = "dark-red"

    cases = [(str, {}, ["x.csv", "-", ""]),
             (float, {}, ["0", "2.2e9", "-1.5", ".5", "3.", "1e-3", "7", "+.5", "-0", "007.5", "1E5", "-.0e-3"]),
             (int, {}, ["0", "-3", "42", "007", "+3", "-0"]), (Colour, {}, ["red", "dark-red", Colour.red]),
             (Optional[float], {}, ["0.25"]), (List[str], {}, [("a", "b"), ()]),
             (float, {}, [2.5]), (int, {}, [3]),
             (float, {"min": 0.0}, ["0", "1", "2.5e3"]), (int, {"max": 3}, [2, "3", "-1"]),     # within their range
             (float, {"min": 0.0, "max": 1.0}, ["0.5", "1", "0"])]
    for ann, kwargs, values in cases:
        desc = _coercion.resolve_type_descriptor(ann, OptionInfo(**kwargs))
        typer_param = _coercion.build_runtime_param(desc)
        for value in values:
            mine = a.plain_value(desc, value)
            assert mine is not a.NOT_PLAIN, (ann, value)
            theirs = typer_param._coerce_value(value, param=None, ctx=None)
            assert type(mine) is type(theirs) and mine == theirs, (ann, value, mine, theirs)
    # left to typer: bad values, numbers out of their range or clamped, non-decimal spellings
    for ann, kwargs, value in [(float, {}, "abc"), (float, {}, "nan"), (float, {}, "1_000"), (float, {}, "1e999"),
                               (int, {}, "1.0"), (float, {"min": 0.0}, "-1"), (int, {"max": 3}, 4),
                               (float, {"min": 0.0, "clamp": True}, "1"), (float, {"max": 1.0}, "1.5"),
                               (Colour, {}, "RED"), (Colour, {}, "blue")]:
        desc = _coercion.resolve_type_descriptor(ann, OptionInfo(**kwargs))
        assert a.plain_value(desc, value) is a.NOT_PLAIN, (ann, kwargs, value)


@pytest.mark.subprocess
def test_the_tour_does_not_import_scipy_optimize(tmp_path):
    """ingest -> smooth -> refine -> estimate of the README tour in one process: none of them
    imports scipy.optimize (or scipy.integrate, which imports it): the noise model's search is
    methods/noise.py's, the root finder methods/roots.py (scipy's iterates, tests/methods/test_roots.py); the
    first three do not import scipy.special either (tests/methods/test_distributions.py)."""
    out = str(tmp_path)
    commands = [
        ["ingest", "sample_data/doppler_pass.csv", "--stations", "sample_data/stations.csv", "--carrier-hz", "2.2e9",
         "--mode", "one-way", "-o", f"{out}/pass.parquet"],
        ["smooth", f"{out}/pass.parquet", "-o", f"{out}/smoothed.parquet"],
        ["refine", f"{out}/smoothed.parquet", "--initial", "sample_data/stale.json", "--doppler-bias", "offset+drift",
         "-o", f"{out}/refined.json"],
        ["estimate", "sample_data/multistation.parquet", "--initial", f"{out}/refined.json", "--apriori-initial",
         "--range-bias", "-o", f"{out}/solution.json"]]
    probe = ("import sys; from trackproc.cli import app as a; "
             f"codes = [a._main(c) for c in {commands[:3]!r}]; "
             "special = 'scipy.special' in sys.modules; "
             f"codes.append(a._main({commands[3]!r})); "
             "print(*codes, 'trackproc.methods.noise' in sys.modules, special, "
             "*[m for m in ('scipy.optimize', 'scipy.integrate') if m in sys.modules])")
    root = __import__("pathlib").Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=root)
    # the refinement ran the REML noise model (methods.noise imported), without scipy.optimize, and
    # ingest -> smooth -> refine without scipy.special (methods/distributions.py: its quantiles)
    assert res.stdout.split() == ["0", "0", "0", "0", "True", "False"], res.stdout + res.stderr[-2000:]


@pytest.mark.subprocess
def test_commands_leave_numpys_unused_modules_unloaded_and_usable(tmp_path):
    """A command does not load numpy.f2py and numpy.testing, which scipy only looks at when it
    starts (cli/app.py ``_defer_unused_numpy_modules``: lazy modules), not even once scipy.linalg
    is imported after it (estimate itself no longer imports it: methods/lapack.py); both still
    work when used afterwards; ``--help`` does not even import numpy."""
    probe = ("import sys, contextlib, io; from trackproc.cli import app as a\n"
             "with contextlib.redirect_stdout(io.StringIO()): h = a._main(['estimate', '--help'])\n"
             "numpy_at_help = 'numpy' in sys.modules\n"
             "code = a._main(['-q', 'estimate', 'sample_data/multistation.parquet', '--initial', "
             f"'sample_data/stale.json', '--apriori-initial', '--range-bias', '-o', '{tmp_path}/s.json'])\n"
             "import scipy.linalg\n"
             "lazy = [type(sys.modules[m]).__name__ == '_LazyModule' for m in a._UNUSED_NUMPY_MODULES]\n"
             "import numpy, numpy.testing; numpy.testing.assert_allclose(1.0, 1.0)\n"
             "print('RESULT', h, numpy_at_help, code, 'scipy.linalg' in sys.modules, *lazy, "
             "type(sys.modules['numpy.testing']).__name__)")
    assert _probe_result(probe) == ["0", "False", "0", "True", "True", "True", "module"]


#: The command words whose help is checked from the cache (the top level and every command).
_HELP_PROBE = ("import io, sys, json; from trackproc.cli import app as a; out = sys.stdout; "
               "sys.stdout = io.StringIO(); code = a._main(json.loads(sys.argv[1])); "
               "text = sys.stdout.getvalue(); sys.stdout = out; "
               "print(json.dumps([code, text, sorted(m for m in ('typer', 'logging', 'trackproc.cli.root', "
               "'trackproc.cli.commands', 'numpy') if m in sys.modules)]))")


def _help(argv, cache):
    import json
    import os

    env = {**os.environ, "TRACKPROC_CACHE_DIR": str(cache)}
    res = subprocess.run([sys.executable, "-c", _HELP_PROBE, json.dumps(argv)], capture_output=True, text=True,
                         check=True, env=env)
    return json.loads(res.stdout)


@pytest.mark.subprocess
def test_help_from_the_cache_is_typers_without_typer(tmp_path):
    """``--help`` renders by typer once; the next run prints the same text without importing typer,
    logging or any command module (cli/help_cache.py); with the cache off it is typer's every time."""
    from trackproc.cli.commands import SUMMARIES

    for argv in [["--help"], ["-h"]] + [[name, "--help"] for name in SUMMARIES]:
        code, rendered, loaded = _help(argv, tmp_path / "cache")
        assert code == 0 and rendered.startswith("Usage: trackproc") and "typer" in loaded, argv
        code, cached, loaded = _help(argv, tmp_path / "cache")
        assert (code, cached, loaded) == (0, rendered, []), argv
        # typer renders it; a command's help imports that command's module alone (cli/root.py _register)
        every = ["trackproc.cli.commands"] if len(argv) == 1 else []
        assert _help(argv, "off")[1:] == [rendered, sorted(["logging", "trackproc.cli.root", "typer", *every])], argv
    assert not (tmp_path / "off").exists()


@pytest.mark.subprocess
def test_a_stale_help_entry_is_rendered_again(tmp_path):
    """An entry whose inputs changed (a module file's stamp, a config file that appeared) or that
    is damaged is not used: typer renders the help again, and the text follows the change."""
    cache = tmp_path / "cache"
    first = _help(["refine", "--help"], cache)
    (entry,) = (cache / "help").glob("*.txt")
    head, _, text = entry.read_text().partition("\n\n")
    lines = head.split("\n")
    stamp = next(i for i, line in enumerate(lines) if line.endswith("/cli/refine_cmd.py"))
    mtime, size, path = lines[stamp].split(" ", 2)
    lines[stamp] = f"{int(mtime) + 1} {size} {path}"              # as if refine_cmd.py had been edited
    entry.write_text("\n".join(lines) + "\n\n" + "stale help\n")
    again = _help(["refine", "--help"], cache)
    assert again == first and "typer" in again[2]
    assert _help(["refine", "--help"], cache) == [0, first[1], []]    # rewritten, used again
    entry.write_text("damaged")
    assert _help(["refine", "--help"], cache) == first
    # a config file's defaults show in the help (click's default_map): its appearance is a change
    config = tmp_path / "config.toml"
    config.write_text('[refine]\ndoppler_bias = "offset"\n')
    import os

    os.environ["TRACKPROC_CONFIG"] = str(config)
    try:
        with_config = _help(["refine", "--help"], cache)
    finally:
        del os.environ["TRACKPROC_CONFIG"]
    assert with_config[0] == 0 and "typer" in with_config[2]


@pytest.mark.subprocess
def test_other_requests_go_to_typer(tmp_path):
    """Only plain help requests are cached: an option before the flag, an unknown command (exit 2)
    and ``--version`` (answered without typer) leave no help entry."""
    cache = tmp_path / "cache"
    assert _help(["refine", "x.csv", "--initial", "s.json", "--help"], cache)[0] == 0
    code, _, loaded = _help(["no-such-command", "--help"], cache)
    assert code == 2 and "typer" in loaded
    code, text, loaded = _help(["--version"], cache)
    assert code == 0 and text.startswith("trackproc ") and loaded == []
    assert not list(cache.glob("help/*.txt"))


@pytest.mark.subprocess
def test_a_command_registers_its_own_module_only():
    """``trackproc COMMAND ...`` imports that command's module, not the fourteen others (cli/root.py
    ``COMMAND_MODULES``, which names the module of every command cli/commands.py registers); the
    top-level help, an unknown name and a config file in force register them all."""
    from trackproc.cli import root

    probe = ("import sys, json; from trackproc.cli import root; names = {}\n"
             "for name, module in root.COMMAND_MODULES.items():\n"
             "    before = {c.name for c in root.app.registered_commands}\n"
             "    root._register(name)\n"
             "    names[name] = sorted({c.name for c in root.app.registered_commands} - before)\n"
             "print(json.dumps([names, 'trackproc.cli.commands' in sys.modules]))")
    import json

    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    names, all_loaded = json.loads(res.stdout)
    assert names == {name: [name] for name in root.COMMAND_MODULES} and not all_loaded
    from trackproc.cli.commands import SUMMARIES

    registered = {c.name for c in root.app.registered_commands}     # cli/commands.py imported above
    assert set(root.COMMAND_MODULES) == set(SUMMARIES) == registered   # every command has its module
    probe = ("import io, sys, contextlib; from trackproc.cli import app as a\n"
             "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
             "    codes = [a._main(['refine', '--help']), a._main(['-q', 'info', 'sample_data/stations.csv'])]\n"
             "print(codes, 'trackproc.cli.commands' in sys.modules, "
             "sorted(m for m in sys.modules if m.startswith('trackproc.cli.') and m.endswith('_cmd')))")
    root_dir = __import__("pathlib").Path(__file__).resolve().parents[2]
    env = {**__import__("os").environ, "TRACKPROC_CACHE_DIR": "off"}
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=root_dir,
                         env=env)
    assert res.stdout.split("]", 1)[1].split()[:1] == ["False"], res.stdout + res.stderr
    assert "'trackproc.cli.info_cmd', 'trackproc.cli.refine_cmd']" in res.stdout, res.stdout
    env["TRACKPROC_CONFIG"] = str(root_dir / "no-such-config.toml")
    res = subprocess.run([sys.executable, "-c", "from trackproc.cli import app as a; import sys; "
                          "code = a._main(['refine', '--help']); print(code)"],
                         capture_output=True, text=True, cwd=root_dir, env=env)
    assert res.stdout.strip() == "2" and "config file not found" in res.stderr     # one line, as before


def test_every_command_has_its_module_for_the_one_command_start_up():
    """cli/root.COMMAND_MODULES names each registered command's module (a command missing there
    would be imported with all the others, or not at all)."""
    import trackproc.cli.commands  # noqa: F401  (registers every command)
    from trackproc.cli import root

    names = {c.name for c in root.app.registered_commands}
    assert names == set(root.COMMAND_MODULES), names ^ set(root.COMMAND_MODULES)


@pytest.mark.subprocess
def test_refine_and_estimate_do_not_import_pandas(tmp_path, run_cli):
    """``refine`` of a smoothed Parquet pass (and of the same pass as CSV, without pandas only) and
    ``estimate`` of a Parquet pass file, each in a
    fresh interpreter, read the pass through numpy columns (types/passes.py ``PassTable.column``)
    and never import pandas (~0.15 s of CPU, a quarter of a refine) or pyarrow.compute (Parquet's
    text columns read as their dictionaries, io/columns.py); ``--residuals`` still writes
    the table, through pandas, and the state file is the same with it."""
    out = str(tmp_path)
    root = __import__("pathlib").Path(__file__).resolve().parents[2]
    prepare = [["-q", "ingest", "sample_data/doppler_pass.csv", "--stations", "sample_data/stations.csv",
                "--carrier-hz", "2.2e9", "--mode", "one-way", "-o", f"{out}/pass.parquet"],
               ["-q", "smooth", f"{out}/pass.parquet", "-o", f"{out}/smoothed.parquet"],
               ["-q", "smooth", f"{out}/pass.parquet", "-o", f"{out}/smoothed.csv"]]
    # the inputs only (this test's subject is the probes' imports below, each in a fresh interpreter)
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(root)
        assert [run_cli(c).exit_code for c in prepare] == [0, 0, 0]
    refine = ["-q", "refine", f"{out}/smoothed.parquet", "--initial", "sample_data/stale.json", "--doppler-bias",
              "offset+drift", "-o"]
    estimate = ["-q", "estimate", "sample_data/multistation.parquet", "--initial", "sample_data/stale.json",
                "--apriori-initial", "--range-bias", "-o", f"{out}/solution.json"]
    probe = ("import sys; from trackproc.cli import app as a; "
             "print(a._main({!r}), 'pandas' in sys.modules, 'pyarrow.compute' in sys.modules)")
    results = [subprocess.run([sys.executable, "-c", probe.format(args)], capture_output=True, text=True,
                              cwd=root) for args in (refine + [f"{out}/refined.json"], estimate,
                                                     refine + [f"{out}/with.json", "--residuals", f"{out}/r.csv"],
                                                     [a.replace(".parquet", ".csv") for a in refine]
                                                     + [f"{out}/from_csv.json"])]
    assert [r.stdout.split()[:3] for r in results[:2]] + [results[2].stdout.split()[:2]] + \
        [results[3].stdout.split()[:2]] == \
        [["0", "False", "False"], ["0", "False", "False"], ["0", "True"], ["0", "False"]], \
        [r.stdout + r.stderr[-1000:] for r in results]
    assert (tmp_path / "refined.json").read_bytes() == (tmp_path / "with.json").read_bytes()
    assert (tmp_path / "r.csv").read_text().count("\n") > 100


@pytest.mark.subprocess
def test_estimate_imports_neither_scipy_linalg_nor_scipy_special_without_an_edited_pass(tmp_path):
    """``estimate`` needs scipy.special (~30 ms of CPU) only for the edited-pass test's binomial
    tail: a run where no pass loses more than 10 % of its samples (the shipped multistation set,
    default editing) does not import it; the run with ``--clip 0`` neither. Nor scipy.linalg
    (~70 ms): the noise model's LAPACK routines come from SciPy's wrapper module alone
    (methods/lapack.py), which is loaded: the noise model ran."""
    root = __import__("pathlib").Path(__file__).resolve().parents[2]
    probe = ("import sys; from trackproc.cli import app as a; "
             "print(a._main({!r}), 'scipy.special' in sys.modules, 'scipy.linalg' in sys.modules, "
             "'scipy.linalg._flapack' in sys.modules)")
    base = ["-q", "estimate", "sample_data/multistation.parquet", "--initial", "sample_data/stale.json",
            "--apriori-initial", "--range-bias", "-o"]
    results = [subprocess.run([sys.executable, "-c", probe.format(args)], capture_output=True, text=True, cwd=root)
               for args in (base + [f"{tmp_path}/a.json"], base + [f"{tmp_path}/b.json", "--clip", "0"])]
    assert [r.stdout.split() for r in results] == [["0", "False", "False", "True"]] * 2, \
        [r.stdout + r.stderr[-1000:] for r in results]


@pytest.mark.subprocess
def test_propagate_does_not_import_pandas(tmp_path):
    """``propagate`` writes Parquet, Arrow, CSV and OEM from numpy columns (io/ephemeris.py,
    io/tables.py's buffer-built Arrow arrays): a fresh interpreter never imports pandas (~0.25 s
    of CPU) or pyarrow.compute, with a station's predictions and a propagated covariance too;
    ``info`` and the ephemeris reader still read what it wrote."""
    root = __import__("pathlib").Path(__file__).resolve().parents[2]
    probe = ("import sys; from trackproc.cli import app as a; "
             "print(a._main({!r}), 'pandas' in sys.modules, 'pyarrow.compute' in sys.modules)")
    base = ["-q", "propagate", "sample_data/stale.json", "--span", "2h", "--step", "60"]
    station = ["--at-station", "ZHY", "--stations", "sample_data/stations.csv", "--carrier-hz", "2.2e9"]
    runs = [base + station + ["-o", f"{tmp_path}/e.parquet"], base + station + ["-o", f"{tmp_path}/e.csv"],
            base + ["--stm", "--format", "arrow", "-o", f"{tmp_path}/e.arrow"],
            base + ["--format", "oem", "-o", f"{tmp_path}/e.oem"]]
    results = [subprocess.run([sys.executable, "-c", probe.format(args)], capture_output=True, text=True, cwd=root)
               for args in runs]
    assert [r.stdout.split() for r in results] == [["0", "False", "False"]] * 4, \
        [r.stdout + r.stderr[-1000:] for r in results]
    from trackproc.io.ephemeris import read_ephemeris

    parquet, csv = read_ephemeris(str(tmp_path / "e.parquet")), read_ephemeris(str(tmp_path / "e.csv"))
    assert len(parquet) == 121 and "doppler_hz" in parquet.columns and "sigma_range_m" in parquet.columns
    assert list(parquet.columns) == list(csv.columns)
    assert __import__("numpy").array_equal(parquet.states, csv.states)
    assert "stm_1_4" in read_ephemeris(str(tmp_path / "e.arrow")).columns
    assert main(["-q", "info", str(tmp_path / "e.parquet")]) == 0


@pytest.mark.subprocess
def test_the_batch_driver_modules_and_the_numpy_deferral_import_no_numpy():
    """A pool's batch driver never needs numpy: the command line's deferral of numpy's unused
    modules (a meta path finder, pipeline/lazy_numpy.py), the batch run's modules and the
    up-front check of a valid ``refine.initial`` (io/statecheck.py) do not import it; numpy
    imported afterwards still meets the deferral (scipy's start-up leaves both modules lazy)."""
    probe = ("import sys; from trackproc.cli import app as a; a._defer_unused_numpy_modules()\n"
             "import trackproc.pipeline.batch.run as r\n"
             "ok = r.certainly_valid(open('sample_data/stale.json', 'rb').read())\n"
             "before = 'numpy' in sys.modules\n"
             "import scipy.linalg\n"
             "print('RESULT', ok, before, *[type(sys.modules[m]).__name__ for m in a._UNUSED_NUMPY_MODULES])")
    assert _probe_result(probe) == ["True", "False", "_LazyModule", "_LazyModule"]


def _probe_result(probe: str) -> list:
    """The words after ``RESULT`` on the last such line ``probe`` prints, run by a fresh Python in
    the project's root (the sample data's paths are relative to it)."""
    root = __import__("pathlib").Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=root)
    last = [line for line in res.stdout.splitlines() if line.startswith("RESULT")]
    assert last, res.stdout[-2000:] + res.stderr[-2000:]
    return last[-1].split()[1:]
