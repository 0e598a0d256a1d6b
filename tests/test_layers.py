"""The layer contract of pyproject.toml ([tool.importlinter]), checked by import-linter on every
``python -m pytest`` run: cli -> report -> pipeline -> io -> types -> methods -> models -> dynamics -> constants, errors;
a module may import only from the layers below its own."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

importlinter = pytest.importorskip("importlinter", reason="import-linter is in the 'test' extra")
from importlinter import configuration  # noqa: E402
from importlinter.application import use_cases  # noqa: E402

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
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

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
