"""The carrier is checked once where it enters (``check_carrier``: ingest's ``--carrier-hz``, a
pass file's metadata when read); the commands that convert Doppler read it through
``stated_carrier``, which trusts the value and makes a missing carrier a one-line input error."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from trackproc.errors import InputError
from trackproc.io.validate import stated_carrier
from trackproc.pipeline.od.samples import merge_tables
from trackproc.types import PassTable


def _table(kind: str, meta: dict) -> PassTable:
    times = pd.date_range("2026-03-20T09:30:00", periods=3, freq="10s", tz="UTC")
    frame = pd.DataFrame({"time": times, "station": "ZHY", "pass_id": 1, "kind": kind,
                          "value": [1.0, 2.0, 3.0], "sigma": 1.0})
    return PassTable(frame, meta)


def test_stated_carrier_is_the_metadata_value_or_the_missing_value():
    assert stated_carrier({"carrier_hz": 2.2e9}) == 2.2e9
    assert math.isnan(stated_carrier({}))
    assert stated_carrier(None, missing=None) is None
    with pytest.raises(InputError) as err:
        stated_carrier({}, file="p.parquet", needed=True)
    assert err.value.column == "carrier_hz" and "p.parquet" in str(err.value) and "\n" not in str(err.value)


def test_doppler_without_a_carrier_is_an_input_error_and_ranges_need_none():
    with pytest.raises(InputError, match="carrier") as err:
        merge_tables([("dop.parquet", _table("doppler", {"doppler_mode": "one-way"}))], None)
    assert err.value.column == "carrier_hz" and "dop.parquet" in str(err.value)
    frame, _ = merge_tables([("rng.parquet", _table("range", {}))], None)
    assert np.isnan(frame["_carrier"]).all()
    frame, _ = merge_tables([("dop.parquet", _table("doppler", {"carrier_hz": 4.37e8}))], None)
    assert (frame["_carrier"] == 4.37e8).all()
