"""Ingest codes its text columns without pandas (``ingest_samples.factorize``): the codes and
distinct values of ``pandas.factorize`` itself, the reference, for labels that are all str (coded
in Python's dicts) and for any other mix (None, NaN, numbers, booleans: handed to pandas); and a
CSV pass file read and ingested in a fresh process imports no pandas."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackproc.pipeline.ingest_samples import factorize

#: few letters: repeated labels, and case / Unicode neighbours that must stay distinct
_TEXT = st.text(alphabet="aAbé\u00e9e\u0301 ", max_size=3)
_OTHER = st.one_of(st.none(), st.just(math.nan), st.just(np.nan), st.integers(-2, 2), st.booleans(),
                   st.floats(allow_nan=True, width=64), st.builds(np.str_, _TEXT))


def _same(values):
    codes, uniques = factorize(np.array(values, dtype=object) if values else np.zeros(0, object))
    ref_codes, ref_uniques = pd.factorize(np.asarray(values, dtype=object), sort=False)
    assert codes.dtype == np.intp
    assert codes.tolist() == ref_codes.tolist(), values
    assert [(type(u), u) for u in uniques] == [(type(u), u) for u in ref_uniques], values


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(_TEXT, max_size=30))
def test_str_labels_as_pandas_codes_them(values):
    _same(values)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(st.one_of(_TEXT, _OTHER), max_size=30))
def test_mixed_labels_as_pandas_codes_them(values):
    _same(values)


def test_cases_the_readers_give():
    _same(["doppler", "elevation", "doppler", "elevation"])
    _same(["Hz", "deg", "", "Hz"])             # an empty unit is a label, not a missing value
    _same(["m", None, "m", math.nan])          # missing: code -1, not among the distinct values
    _same([np.str_("CPH"), "CPH", "ZHY"])      # numpy's str: equal to str, the first one kept
    _same([])


_PROBE = """
import sys
from pathlib import Path
import pyarrow.csv   # as the batch's ingest step: small CSV files are then read by Arrow's reader
from trackproc.io.stations import parse_stations
from trackproc.pipeline.batch.steps import _read_input
from trackproc.pipeline.ingest import IngestOptions, ingest

data = Path(sys.argv[1]).read_bytes()
opt = {"layout": "auto", "carrier_hz": 2.2e9, "drop_invalid": False}
raw = _read_input(data, sys.argv[1], opt)
stations = parse_stations(Path(sys.argv[2]).read_bytes(), sys.argv[2])
result = ingest([raw], stations, IngestOptions(carrier_hz=2.2e9, doppler_mode="one-way"))
table = result.table
print(len(table.column("time")), sorted(set(table.column("kind"))), "pandas" in sys.modules)
"""


@pytest.mark.subprocess
def test_a_csv_pass_file_is_ingested_without_pandas(tmp_path):
    rows = [f"2026-03-20T09:30:{s:02d}.000000Z,CPH,{-3846.3 - 390 * s},{66.1 - 0.1 * s}" for s in range(40)]
    # 40 rows + header: big enough for Arrow's CSV reader (the batch's path), small enough to be fast
    (tmp_path / "p.csv").write_text("time,station,doppler_hz,elevation_deg\n" + "\n".join(rows) + "\n")
    (tmp_path / "s.csv").write_text("station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\n")
    done = subprocess.run([sys.executable, "-c", _PROBE, str(tmp_path / "p.csv"), str(tmp_path / "s.csv")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["80", "['doppler',", "'elevation']", "False"], done.stdout
