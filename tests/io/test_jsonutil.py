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


def _unready(rng: random.Random, value):
    """``value`` with some leaves and containers swapped for what json_ready converts: numpy
    scalars and arrays, non-finite floats, datetime64, int/bool/None keys, dict and list subclasses."""
    r = rng.random()
    if isinstance(value, dict):
        out = {k: _unready(rng, v) for k, v in value.items()}
        if r < 0.15:
            out[rng.choice([7, 10, True, None, 2.5])] = rng.choice([1.0, "k"])
        return _Dict(out) if r > 0.95 else out
    if isinstance(value, (list, tuple)):
        out = [_unready(rng, v) for v in value]
        if r < 0.1 and out and all(type(v) is float for v in out):
            return np.array(out)
        return _List(out) if r > 0.95 else out
    if type(value) is float:
        if r >= 0.2:
            return value
        return rng.choice([value, np.float64(value), float("nan"), float("-inf"), np.float32(0.5)])
    if type(value) is int and -2**63 < value < 2**63:
        return np.int64(value) if r < 0.2 else value
    if value is None and r < 0.2:
        return np.datetime64("2026-03-20T09:30:00.123456789")
    return value


class _Dict(dict):
    pass


class _List(list):
    pass


@pytest.mark.parametrize("seed", range(3))
def test_dumps_in_one_walk_is_json_dumps_of_json_ready(seed):
    """dumps (json_ready's conversion where it is needed, in the emitting walk) against the
    standard library's indented text of the fully converted value."""
    rng = random.Random(seed)
    for _ in range(400):
        value = _unready(rng, {"v": _value(rng), "w": [_value(rng) for _ in range(3)]})
        want = json.dumps(json_ready(value), indent=2, sort_keys=True, allow_nan=False) + "\n"
        assert dumps(value) == want, value


def test_scalar_containers_at_every_depth():
    """The containers of scalars that the C encoder writes in one call, at several depths, with
    strings holding separators and control characters: the standard library's text."""
    value = {"a": {"s": "x,\n  y", "n": None, "t": True, "f": -0.0, "i": 2**70, "e": "é\u2028"},
             "b": [[{"k": 1.5, "j": "]"}, ["a", None, False]], []], "c": {}, "d": ["", 1, 0.1]}
    for indent in (1, 2, 4):
        for sort_keys in (False, True):
            assert dumps_indented(value, indent, sort_keys) == json.dumps(value, indent=indent, sort_keys=sort_keys)
    assert dumps(value) == json.dumps(value, indent=2, sort_keys=True) + "\n"
