"""io/statecheck.py: the numpy-free up-front check of a batch's ``refine.initial`` says "certainly
valid" only for files the state file reader (io/statefile.parse_state, the reference) accepts
without a warning; it is not a second reader (anything unsure goes to the reader)."""

from __future__ import annotations

import copy
import json
import math
import random
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from trackproc.errors import InputError
from trackproc.io import statecheck, statefile
from trackproc.types import checks, state

ROOT = Path(__file__).resolve().parents[2]
STALE = (ROOT / "sample_data" / "stale.json").read_bytes()


def _accepted(data: bytes) -> bool:
    """The reader accepts ``data`` without any warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            statefile.parse_state(data, "x.json")
        except (InputError, Warning):
            return False
    return True


def test_its_copies_of_the_readers_bounds_are_the_readers():
    assert statecheck.ORBIT_RADIUS_RANGE_M == checks.ORBIT_RADIUS_RANGE_M
    assert statecheck.MIN_SPEED_FRACTION == checks.MIN_SPEED_FRACTION
    assert statecheck.STATE_PARAMETERS == state.STATE_PARAMETERS


def test_its_years_convert_without_erfas_dubious_year():
    """The installed ERFA converts the first and last instants of :data:`YEARS` with status 0."""
    import erfa

    first, last = statecheck.YEARS
    assert erfa.ufunc.dtf2d("UTC", first, 1, 1, 0, 0, 0.0)[2] == 0
    assert erfa.ufunc.dtf2d("UTC", last, 12, 31, 23, 59, 59.999999999)[2] == 0


def test_the_sample_state_and_a_written_state_are_certainly_valid():
    """The files a nightly batch is given: sample_data/stale.json and a state as trackproc writes it
    (values, sigma, covariance, elements, diagnostics)."""
    written = statefile.state_json(statefile.parse_state(STALE, "stale.json")).encode()
    assert statecheck.certainly_valid(STALE)
    assert statecheck.certainly_valid(written)
    assert _accepted(written)


def _mutations(rng: random.Random, doc: dict) -> dict:
    """``doc`` with one to three random changes, many of them at or near the reader's bounds."""
    doc = copy.deepcopy(doc)
    for _ in range(rng.randint(1, 3)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                _mutate(rng, doc, rng.randrange(16))
            except (TypeError, ValueError, IndexError, KeyError, AttributeError, ArithmeticError):
                pass                  # a change that does not apply to this document
    return doc


def _mutate(rng: random.Random, doc: dict, what: int) -> None:
    if True:
        n = len(doc.get("parameters") or [])
        if what == 0:      # the radius near its bounds (and a km state)
            scale = rng.choice([6.356e6, 1.5e9, 1.0e5, 1e3]) * (1 + rng.choice([-1, 1]) * 10.0 ** rng.uniform(-12, -3))
            r = np.asarray(doc["position_m"], float)
            doc["position_m"] = (r / np.linalg.norm(r) * scale).tolist()
        elif what == 1:    # the speed near escape, near the low bound, or in km/s
            radius = float(np.linalg.norm(doc["position_m"]))
            escape = math.sqrt(2 * checks.MU_EARTH / radius)
            speed = rng.choice([escape, 0.05 * escape / math.sqrt(2), 7.5]) * (1 + rng.uniform(-1e-5, 1e-5))
            v = np.asarray(doc["velocity_m_s"], float)
            doc["velocity_m_s"] = (v / np.linalg.norm(v) * speed).tolist()
        elif what == 2:
            doc["frame"] = rng.choice(["GCRF", "gcrs", "ICRF", "EME2000", "J2000", "TEME", "ITRF", "ecef", "", 3, None])
        elif what == 3:
            doc["epoch"] = rng.choice(["2026-03-20T09:30:00.000Z", "2026-03-20T09:30:00Z", "2026-03-20T09:30:00",
                                       "2026-03-20 09:30:00Z", "2026-03-20T09:30:00+02:00", "2026-02-30T00:00:00Z",
                                       "2028-12-31T23:59:59Z", "2027-12-31T23:59:59.999999999Z", "1959-01-01T00:00:00Z",
                                       "1972-01-01T00:00:00Z", "2016-12-31T23:59:60Z", "2300-01-01T00:00:00Z",
                                       "2026-03-20T24:00:00Z", "2026-03-20T09:30:00.0000000001Z", "", 5])
        elif what == 4:    # a covariance entry: asymmetric, a negative or a near-singular matrix
            if doc.get("covariance"):
                i, j = rng.randrange(n), rng.randrange(n)
                cov = doc["covariance"]
                root = math.sqrt(abs(cov[i][i] * cov[j][j])) or 1.0
                cov[i][j] = root * rng.choice([1.0, -1.0, 0.999999999, 1.0 + 1e-9, 2e-10, 1.5]) * rng.choice([1, -1])
                if rng.random() < 0.6:
                    cov[j][i] = cov[i][j]
        elif what == 5:    # sigma against the covariance's diagonal, near the reader's 1e-6
            if doc.get("sigma"):
                i = rng.randrange(n)
                doc["sigma"][i] *= 1 + rng.choice([-1, 1]) * 10.0 ** rng.uniform(-8, -4)
        elif what == 6:    # values against the state, near the reader's 1e-6 m
            if doc.get("values"):
                i = rng.randrange(min(n, 6))
                doc["values"][i] += rng.choice([-1, 1]) * 10.0 ** rng.uniform(-8, -4)
        elif what == 7:
            doc.pop(rng.choice(["parameters", "sigma", "covariance", "values", "epoch", "position_m", "frame"]), None)
        elif what == 8:
            key = rng.choice(["position_m", "velocity_m_s", "sigma", "values"])
            if doc.get(key):
                bad = rng.choice([True, "1", None, float("nan"), float("inf"), 10 ** 400])
                doc[key][rng.randrange(len(doc[key]))] = bad
        elif what == 9:
            if doc.get("parameters"):
                doc["parameters"][rng.randrange(n)] = rng.choice(["x", "", 3, "range_bias:A"])
        elif what == 10:
            doc[rng.choice(["constants", "diagnostics"])] = rng.choice([{}, {"a": 1}, [], [1], "text", 0, None])
        elif what == 11:
            doc["force_model"] = rng.choice(["two-body+J2", "j2", 2, None, ["j2"]])
        elif what == 12:
            doc["schema_version"] = rng.choice([0, 1, 2, True, "1", 1.0, -1])
        elif what == 13:   # a shorter or longer list
            key = rng.choice(["position_m", "velocity_m_s", "sigma", "values", "covariance", "parameters"])
            if doc.get(key):
                doc[key] = doc[key][:-1] if rng.random() < 0.5 else doc[key] + doc[key][:1]
        elif what == 14:   # a sigma of zero or below
            if doc.get("sigma"):
                doc["sigma"][rng.randrange(n)] = rng.choice([0.0, -1e-300, -1.0])
        else:              # a seventh parameter with its row and column
            if doc.get("covariance") is not None and n == 6:
                doc["parameters"].append("range_bias:ZHY")
                for key in ("values", "sigma"):
                    if doc.get(key):
                        doc[key].append(rng.choice([0.0, 1.0]))
                cov = doc["covariance"]
                for row in cov:
                    row.append(0.0)
                cov.append([0.0] * 6 + [rng.choice([1.0, 0.0])])


def test_certainly_valid_files_are_accepted_by_the_reader():
    """On ~3000 mutated state documents, none that the check calls certainly valid is refused (or
    warned about) by the reader; the check says "certainly valid" for many of them and "unsure"
    for every kind of error (so both answers are exercised)."""
    rng = random.Random(20261129)
    stale = json.loads(STALE)
    written = json.loads(statefile.state_json(statefile.parse_state(STALE, "stale.json")))
    counts = {(True, True): 0, (False, True): 0, (False, False): 0}
    for k in range(3000):
        doc = _mutations(rng, stale if k % 2 else written)
        data = json.dumps(doc).encode()
        quick, accepted = statecheck.certainly_valid(data), _accepted(data)
        assert not (quick and not accepted), data[:600]
        counts[quick, accepted] += 1
    assert min(counts.values()) > 150, counts


@pytest.mark.parametrize("data", [b"", b"[]", b"{", b"\xff\xfe{}", b"1 ISS\n2 ...",
                                  b'{"epoch": "2026-03-20T09:30:00Z"}'])
def test_anything_else_is_left_to_the_reader(data):
    assert not statecheck.certainly_valid(data)


def test_the_check_imports_no_numpy():
    probe = ("import sys; from trackproc.io.statecheck import certainly_valid; "
             f"print(certainly_valid(open({str(ROOT / 'sample_data' / 'stale.json')!r}, 'rb').read()), "
             "'numpy' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == ["True", "False"], done.stderr[-2000:]
