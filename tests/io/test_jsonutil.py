"""io/jsonutil.py ``dumps_indented``: the text of ``json.dumps(value, indent=..., sort_keys=...,
allow_nan=False)`` (the reference: the standard library) byte for byte, on random nested values
and on a real pass's outputs, and the same errors where json.dumps has them."""

from __future__ import annotations

import json
import random

import numpy as np
import pytest

from trackproc.io.jsonutil import dumps, dumps_compact, dumps_indented, json_ready

_LEAVES = [0.1, -0.0, 5e-324, 1e308, 1e-300, 123456789.125, 2**70, -3, 0, True, False, None, "", "a,b",
           "é \"quoted\"\n\ttab", "\u2028 σ", "[1,2]"]


def _value(rng: random.Random, depth: int = 0):
    r = rng.random()
    if depth > 4 or r < 0.3:
        return rng.choice(_LEAVES + [rng.uniform(-1e6, 1e6), rng.randint(-10**20, 10**20)])
    if r < 0.5:        # a list of numbers (the fast path), ints and floats mixed, or one of bools
        return [rng.choice([rng.uniform(-1, 1), rng.randint(-5, 5), 1e-17]) for _ in range(rng.randint(0, 7))] \
            if rng.random() < 0.9 else [True, 1, 0.5]
    if r < 0.6:        # a matrix of numbers (the one-call path): ragged, empty or bool rows too
        rows = [[rng.choice([rng.uniform(-1, 1), rng.randint(-5, 5), 5e-324, -0.0])
                 for _ in range(rng.randint(1, 6))] for _ in range(rng.randint(1, 5))]
        if rng.random() < 0.1:
            rows.append(rng.choice([[], [True, 1.0], [1.0, "a,b"], (1.0, 2.0), [[1.0]]]))
        return rows
    if r < 0.75:
        seq = [_value(rng, depth + 1) for _ in range(rng.randint(0, 5))]
        return tuple(seq) if rng.random() < 0.1 else seq
    return {rng.choice(["a", "b", "é", 'z"', "key", "0", ""]) + str(rng.randint(0, 9)): _value(rng, depth + 1)
            for _ in range(rng.randint(0, 5))}


@pytest.mark.parametrize("seed", range(4))
def test_same_text_as_json_dumps(seed):
    rng = random.Random(seed)
    for _ in range(500):
        value = _value(rng)
        for indent in (2, 4):
            for sort_keys in (False, True):
                want = json.dumps(value, indent=indent, sort_keys=sort_keys, allow_nan=False)
                assert dumps_indented(value, indent, sort_keys) == want, value


def test_same_errors_and_fallbacks_as_json_dumps():
    for value in ([1.0, float("nan")], {"a": float("inf")}, float("-inf"), {"a": {1, 2}},
                  [[1.0, 2.0], [float("nan"), 1.0]], [[1.0], [float("-inf")]]):
        with pytest.raises((ValueError, TypeError)) as mine:
            dumps_indented(value)
        with pytest.raises((ValueError, TypeError)) as theirs:
            json.dumps(value, indent=2, allow_nan=False)
        assert type(mine.value) is type(theirs.value)
    for value in ({1: "int key"}, {1: "x", "1": "y"}, [np.float64(1.5)], {"a": (1, [2.5])}):
        assert dumps_indented(value) == json.dumps(value, indent=2, allow_nan=False)


def test_a_pass_outputs_text_is_unchanged():
    """dumps (sorted keys, json_ready) and a state-like document with arrays, nested dicts and
    non-finite numbers (null after json_ready)."""
    rng = np.random.default_rng(3)
    doc = {"covariance": rng.normal(size=(7, 7)), "residuals": rng.normal(size=650), "epoch": np.datetime64(
        "2026-03-20T09:30:00.123456789"), "quality": {"verdict": "ok", "reasons": [{"code": "x", "value": np.nan,
                                                                                       "limit": np.float64(1.26)}]},
           "counts": np.arange(5), "flags": np.array([True, False])}
    ready = json_ready(doc)
    assert dumps(doc) == json.dumps(ready, indent=2, sort_keys=True, allow_nan=False) + "\n"
    assert dumps(doc, indent=None) == json.dumps(ready, sort_keys=True, allow_nan=False) + "\n"


@pytest.mark.parametrize("seed", range(2))
def test_compact_text_holds_the_indented_texts_values(seed):
    """dumps_compact (the batch's manifests and .smooth.json): one line, no whitespace outside
    strings, and parsed back the same values (every float bit for bit) as the indented text of
    dumps, the reference being json.loads of each."""
    rng = random.Random(seed)
    for _ in range(300):
        value = {"v": _value(rng), "nan": float("nan"), "x": np.float64(rng.uniform(-1, 1))}
        compact, indented = dumps_compact(value), dumps(value)
        assert compact.endswith("\n") and compact.count("\n") == 1
        assert json.loads(compact) == json.loads(indented)
        assert len(compact) <= len(indented)
        ready = json_ready(value)
        assert dumps_compact(ready, sort_keys=False, ready=True) == json.dumps(
            ready, allow_nan=False, separators=(",", ":")) + "\n"
    floats = [rng.uniform(-1e3, 1e3) for _ in range(200)] + [5e-324, -0.0, 1e308]
    back = json.loads(dumps_compact({"f": floats}))["f"]
    assert [f.hex() for f in back] == [f.hex() for f in floats]
