"""The recorded output set (tests/golden/): every case re-run in-process and compared with its recording,
numbers within 1e-7 relative (absolute floor 1e-9 of their column's or array's largest value; residuals
within 1e-5 in their unit; solution diagnostics 1e-4: tests/golden/record.py says why each tolerance is what
it is), text exactly. A difference is a behaviour change: fix it, or re-record with ``tests/golden/record.py`` and
say why in the commit message."""

from __future__ import annotations

import copy
import importlib.util
import json
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location("golden_record", Path(__file__).parent / "golden" / "record.py")
record = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(record)


@pytest.mark.parametrize("name", sorted(record.CASES))
def test_outputs_match_the_recording(name, tmp_path):
    path = record.golden_path(name)
    assert path.exists(), f"{path.name} missing: run PYTHONPATH=src python tests/golden/record.py {name}"
    expected = json.loads(path.read_text())
    actual = json.loads(json.dumps(record.run_case(name, tmp_path)))  # the recording's JSON round trip
    diff = record.compare(expected, actual, rtol=record.CASE_RTOL.get(name, record.RTOL))
    assert not diff, (f"{name}: outputs differ from the recording (if intended, re-record with "
                      f"PYTHONPATH=src python tests/golden/record.py {name} and say why):\n  " + "\n  ".join(diff))


def test_every_recording_has_a_case_and_the_set_stays_small():
    files = sorted(p for p in record.HERE.glob("*.json"))
    assert {p.stem for p in files} == set(record.CASES)
    assert sum(p.stat().st_size for p in files) < 256_000   # 211 kB with the quality, noise and elements fields


def _first_number(node, path=()):
    """Path to the first non-zero number (and its array's scale) in a recording."""
    if isinstance(node, dict):
        items = sorted(node.items())
    elif isinstance(node, list):
        items = list(enumerate(node))
    else:
        return None
    for key, value in items:
        if record._is_number(value) and value != 0 and abs(value) > 1:
            return path + (key,)
        found = _first_number(value, path + (key,))
        if found:
            return found
    return None


def _set(node, path, value):
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value


def test_comparison_flags_a_change_of_1e_6_and_passes_1e_9():
    expected = json.loads(record.golden_path("refine_seed004").read_text())
    where = _first_number(expected["files"]["pw.json"])
    assert where, "no number found"
    full = ("files", "pw.json") + where
    value = expected
    for key in full:
        value = value[key]
    for relative, flagged in ((1e-6, True), (-1e-6, True), (1e-9, False)):
        changed = copy.deepcopy(expected)
        _set(changed, full, value * (1 + relative))
        assert bool(record.compare(expected, changed)) is flagged, (full, relative)
    changed = copy.deepcopy(expected)
    _set(changed, ("files", "pw.json", "json", "frame"), "EME2000")
    assert record.compare(expected, changed)


def test_comparison_rules():
    compare = record.compare
    assert compare({"a": [1.0, 1e6]}, {"a": [1.0 + 1e-4, 1e6]}) == []          # floor: 1e-9 of the array's 1e6
    assert compare({"a": [1.0, 1e6]}, {"a": [1.0 + 1e-2, 1e6]})
    assert compare({"residual": [3.7]}, {"residual": [3.7 + 6e-7]}) == []      # residuals: 1e-5 absolute
    assert compare({"residual": [3.7]}, {"residual": [3.7 + 1e-4]})
    sums = {"residual": {"numbers": [41.078, 2852.3], "count": 100}}           # a sum: 1e-5 per value
    assert compare(sums, {"residual": {"numbers": [41.078 + 5e-4, 2852.3], "count": 100}}) == []
    assert compare(sums, {"residual": {"numbers": [41.078 + 5e-3, 2852.3], "count": 100}})
    assert compare({"text": [["x ", 1.0, " ", 1e6]]}, {"text": [["x ", 1.0 + 1e-6, " ", 1e6]]})  # text: no floor
    assert compare({"relative": [1e-16]}, {"relative": [5e-13]}) == []         # rounding noise by construction
    assert compare({"relative": [1e-16]}, {"relative": [5e-12]})
    assert compare({"s": "a"}, {"s": "b"}) and compare({"n": 1}, {"n": True}) and compare({"a": [1]}, {"a": [1, 2]})
    assert compare({"a": 1}, {"a": 1, "b": 2}) and compare({"a": 1, "b": 2}, {"a": 1})
    assert record._tokens("EPOCH = 2026-03-20T09:30:00.000 J2 x -4.5e-3") == [
        "EPOCH = 2026-03-20T09:30:00.000 J2 x ", -4.5e-3]
