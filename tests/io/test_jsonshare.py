"""io.jsonshare.dumps_shared against the standard library's json.dumps (the reference): the same
text for drawn records with shared float lists, in both key orders, after in-place changes of a
list already encoded, and the same error where json.dumps raises."""

import json
import math
import random

import numpy as np
import pytest

from trackproc.io import jsonshare
from trackproc.io.jsonshare import dumps_shared
from trackproc.io.passfile import _json_default, meta_json

SORTED = dict(sort_keys=True, separators=(",", ":"), allow_nan=False, default=_json_default)
INSERTION = dict(separators=(",", ":"), allow_nan=False)


def _float(rng):
    return rng.choice([rng.uniform(-1, 1), rng.uniform(-1, 1) * 10.0 ** rng.randint(-320, 308), 0.0, -0.0,
                       5e-324, 1e16, 0.1, -2.5e-9, float(rng.randint(-9, 9))])


def _record(rng, n):
    cov = [[_float(rng) for _ in range(n)] for _ in range(n)]
    return {"station": rng.choice(["CPH", "z\u00e9", "\x00jsonshare 1\x00"]), "degree": n - 1,
            "coefficients": [_float(rng) for _ in range(n)], "covariance_scaled": cov,
            "covariance_unscaled": [row[:] for row in cov], "bic": {str(d): _float(rng) for d in range(n)},
            "short": [_float(rng) for _ in range(3)], "mixed": [1.0] * 9 + [1], "ints": list(range(12)),
            "nested": {"b": [[_float(rng)] * 9, [0.5] * 2], "a": None, "c": [True, "x", 2.0]}}


@pytest.mark.parametrize("seed", range(12))
def test_the_same_text_as_json_dumps_in_both_orders_and_again(seed):
    rng = random.Random(seed)
    summary = {"z": 1, "fits": [_record(rng, rng.randint(1, 16)) for _ in range(rng.randint(1, 4))], "a": "\u2603"}
    meta = {"units": {"doppler": "Hz"}, "smoothing": {**summary, "output": "samples"}, "x": np.float64(0.25)}
    for _ in range(2):   # the second time from the memo
        assert dumps_shared(summary, json.JSONEncoder(**INSERTION)) == json.dumps(summary, **INSERTION)
        assert dumps_shared(meta, json.JSONEncoder(**SORTED)) == json.dumps(meta, **SORTED)
        assert meta_json(meta) == json.dumps(meta, **SORTED)


def test_a_list_changed_in_place_is_encoded_again():
    row = [0.0] + [1.5] * 9
    value = {"m": [row[:], row[:]], "v": row}
    enc = json.JSONEncoder(**SORTED)
    assert dumps_shared(value, enc) == json.dumps(value, **SORTED)
    value["v"][0] = -0.0              # equal to 0.0, other text
    value["m"][1][0] = 0              # equal to 0.0, other text
    assert dumps_shared(value, enc) == json.dumps(value, **SORTED)
    assert '"v":[-0.0,' in dumps_shared(value, enc)
    value["m"][0] = [2.0] * 10        # a row replaced
    value["v"].append(3.0)
    assert dumps_shared(value, enc) == json.dumps(value, **SORTED)


def test_a_string_spelled_like_the_token_and_the_errors():
    enc = json.JSONEncoder(**SORTED)
    tokens = {"t%d" % i: "\x00jsonshare %d\x00" % i for i in range(0, 200000, 997)}
    value = {"v": [1.0] * 10, **tokens}
    for _ in range(3):
        assert dumps_shared(value, enc) == json.dumps(value, **SORTED)
    for bad in ({"v": [1.0] * 9 + [math.nan]}, {"v": [1.0] * 10, "o": object()},
                {"w": [math.inf], "v": [1.0] * 10}):
        with pytest.raises((ValueError, TypeError)) as ours:
            dumps_shared(bad, enc)
        with pytest.raises(type(ours.value)) as theirs:
            json.dumps(bad, **SORTED)
        assert str(ours.value) == str(theirs.value)
    cyclic = {"v": [1.0] * 10}
    cyclic["self"] = cyclic
    with pytest.raises(ValueError, match="Circular reference"):
        dumps_shared(cyclic, enc)


def test_other_encoders_are_left_alone():
    value = {"v": [0.5] * 10, "w": [[1.5] * 9] * 2}
    for kwargs in ({"indent": 1, "separators": (",", ":"), "allow_nan": False}, {"allow_nan": False},
                   {"allow_nan": True, "separators": (",", ":")}):
        assert dumps_shared(value, json.JSONEncoder(**kwargs)) == json.dumps(value, **kwargs)


def test_the_memo_stays_small():
    enc = json.JSONEncoder(**INSERTION)
    for i in range(3 * jsonshare.MEMO_SIZE):
        assert dumps_shared({"v": [float(i)] * 10}, enc) == json.dumps({"v": [float(i)] * 10}, **INSERTION)
    assert len(jsonshare._MEMO) <= jsonshare.MEMO_SIZE
