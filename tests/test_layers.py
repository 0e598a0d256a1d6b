"""The layer contract of pyproject.toml ([tool.importlinter]), checked by import-linter on every
``python -m pytest`` run: cli -> report -> pipeline -> io -> types -> methods -> models -> dynamics -> constants, errors;
a module may import only from the layers below its own; and the test folders tests/<layer>/ mirror the layers."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

importlinter = pytest.importorskip("importlinter", reason="import-linter is in the 'test' extra")
from importlinter import configuration  # noqa: E402
from importlinter.application import use_cases  # noqa: E402

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

configuration.configure()  # what the lint-imports command does first (readers, graph builder, printer)

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"


def _lint(config: Path) -> bool:
    # cache_dir=None: no .import_linter_cache in the checkout (and nothing shared between xdist workers).
    return use_cases.lint_imports(config_filename=str(config), cache_dir=None, no_logo=True)


def test_checked_package_is_this_checkout():
    import trackproc

    assert Path(trackproc.__file__).resolve().is_relative_to(ROOT / "src"), (
        f"import-linter would analyse {trackproc.__file__}, not this checkout's src/")


def test_layer_contract_is_kept():
    # On failure the broken imports (importer -> imported, with line numbers) are in the captured stdout.
    assert _lint(PYPROJECT), "layer contract broken: see the import-linter report above"


def test_contract_catches_an_upward_import(tmp_path, monkeypatch):
    """The same contract on a toy package whose dynamics layer imports the cli layer must fail, and
    pass once that import is removed: the check above can fail."""
    contract = tomllib.loads(PYPROJECT.read_text())["tool"]["importlinter"]["contracts"][0]
    layers = [name.strip() for layer in contract["layers"] for name in layer.split("|")]
    pkg = tmp_path / "layerprobe"
    for name in [n for n in layers if not n.startswith("(")]:    # "(name)": an optional layer, left out
        (pkg / name).mkdir(parents=True)
        (pkg / name / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "__main__.py").write_text("")
    probe = pkg / "dynamics" / "__init__.py"
    probe.write_text("import layerprobe.cli\n")
    quoted = ", ".join(f'"{layer}"' for layer in contract["layers"])
    config = tmp_path / "pyproject.toml"
    config.write_text(
        '[tool.importlinter]\nroot_package = "layerprobe"\n\n[[tool.importlinter.contracts]]\n'
        f'name = "probe"\ntype = "layers"\ncontainers = ["layerprobe"]\nlayers = [{quoted}]\n'
        + (f"exhaustive = true\nexhaustive_ignores = {contract['exhaustive_ignores']!r}\n".replace("'", '"')
           if contract.get("exhaustive") else ""))
    monkeypatch.syspath_prepend(str(tmp_path))
    for mod in [m for m in sys.modules if m == "layerprobe" or m.startswith("layerprobe.")]:
        monkeypatch.delitem(sys.modules, mod)
    assert not _lint(config)
    probe.write_text("")
    assert _lint(config)


# --- the test folders mirror the layers ---------------------------------------------------------------
#: the whole-package checks (this file, the golden outputs) and the tests of the leaf modules stay at the root
ROOT_TESTS = {"test_layers.py", "test_golden.py", "test_isotime.py"}
#: the layers of the contract, top first, without the leaves ("constants | errors | ...")
LAYERS = [layer for layer in
          tomllib.loads(PYPROJECT.read_text())["tool"]["importlinter"]["contracts"][0]["layers"]
          if "|" not in layer]
_IMPORT = re.compile(r"\btrackproc\.(" + "|".join(LAYERS) + r")\b")
#: runs the command line: the in-process runners of conftest, typer's, ``python -m trackproc`` or a bash recipe
_RUNS_CLI = re.compile(r"\brun_cli\b|\bcli_app\b|CliRunner|[\"']-m[\"'],\s*[\"']trackproc|[\"']bash[\"']")


def test_folder(text: str) -> str | None:
    """The folder of a test module: the highest layer it imports, the CLI when it runs commands."""
    found = set(_IMPORT.findall(text)) | ({"cli"} if _RUNS_CLI.search(text) else set())
    return min(found, key=LAYERS.index) if found else None


test_folder.__test__ = False  # a helper, not a test


def test_test_folder_rule():
    assert LAYERS[0] == "cli" and LAYERS[-1] == "dynamics" and "types" in LAYERS
    assert test_folder("from trackproc.dynamics import kepler\nfrom trackproc.io.tdm import read\n") == "io"
    assert test_folder("from trackproc.models.x import y\n\ndef test_a(run_cli):\n    pass\n") == "cli"
    assert test_folder("import subprocess\nsubprocess.run([sys.executable, '-c', 'import trackproc.dynamics'])"
                       ) == "dynamics"
    assert test_folder("from trackproc.isotime import iso_utc\n") is None


def test_each_test_module_sits_in_the_folder_of_its_layer():
    """tests/<layer>/test_*.py for the highest layer a module exercises (README "Tests"); a new test file
    is placed by this rule (``git mv``), so that ``pytest tests/<layer>`` runs that layer's tests."""
    tests = ROOT / "tests"
    wrong = []
    for path in sorted(tests.glob("test_*.py")) + sorted(tests.glob("*/test_*.py")):
        where = path.parent.name if path.parent != tests else None
        if path.name in ROOT_TESTS and where is None:
            continue
        want = test_folder(path.read_text(encoding="utf-8"))
        if where != want:
            wrong.append(f"{path.relative_to(ROOT)} -> tests/{want or '.'}/{path.name}")
    assert not wrong, "move (git mv): " + "; ".join(wrong)
