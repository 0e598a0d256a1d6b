"""The force kernels compiled without a CPython wrapper (``compiled._INNER``: only other kernels call
them, and numba would otherwise compile a wrapper for each) are never called from Python, where
such a call crashes the process instead of raising. Checked on the source: no plain Python
function of compiled.py and no other module of the package or the tests names one."""

import ast
import re
from pathlib import Path

import pytest

pytest.importorskip("numba")

from trackproc.dynamics.forces import compiled  # noqa: E402

ROOT = Path(compiled.__file__).resolve().parents[4]          # src/trackproc/dynamics/forces/compiled.py


def _inner() -> set:
    return {name for name, obj in vars(compiled).items()
            if getattr(obj, "targetoptions", {}).get("no_cpython_wrapper")}


def test_the_wrapperless_kernels_are_called_by_kernels_only():
    inner = _inner()
    assert "_rhs" in inner and "integrate" not in inner        # the entry points keep their wrapper
    here = Path(compiled.__file__).resolve()
    files = sorted((ROOT / "src").rglob("*.py")) + sorted((ROOT / "tests").rglob("*.py"))
    texts = {path: path.read_text() for path in files if path.resolve() != here}
    # kernels run as Python through .py_func: whatever they call is called from Python too
    run_as_python = {m for text in texts.values() for m in re.findall(r"\bcompiled\.(\w+)\.py_func\b", text)}
    assert "_interp2" in run_as_python                            # tests/io/test_forces_jit.py
    tree = ast.parse(here.read_text())
    functions = [f for f in tree.body if isinstance(f, ast.FunctionDef)]
    python_functions = [f for f in functions if not f.decorator_list or f.name in run_as_python]
    assert {f.name for f in python_functions} >= {"perturbation", "partials", "_interp2"}
    for f in python_functions:
        named = {n.id for n in ast.walk(f) if isinstance(n, ast.Name)}
        assert not named & inner, (f.name, named & inner)
    pattern = re.compile(r"\bcompiled\.(" + "|".join(sorted(inner)) + r")\b"
                         r"|\bforces\.compiled import[^\n]*\b(" + "|".join(sorted(inner)) + r")\b")
    for path, text in texts.items():
        found = pattern.search(text)
        assert found is None, (str(path.relative_to(ROOT)), found.group(0))
