"""The batch's stations table, parsed once per process and content (``steps._stations``): the
same stations as a fresh parse, a changed file read anew, an invalid one an error every time."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from trackproc.errors import InputError
from trackproc.io import stations as stations_io
from trackproc.pipeline.batch import steps

A = b"station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\nZHY,50.25,28.66,230\n"
B = b"station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,31\n"
BAD = b"station,lat_deg,lon_deg,height_m\nCPH,95.0,12.55,30\n"


def test_stations_parsed_once_per_content(monkeypatch):
    calls = []
    parse = stations_io.parse_stations
    monkeypatch.setattr(stations_io, "parse_stations", lambda data, source: calls.append(source) or parse(data, source))
    ctx = SimpleNamespace(files={"ingest.stations": A}, paths={"ingest.stations": "s.csv"})
    first, second = steps._stations(ctx), steps._stations(ctx)
    assert first == second == parse(A, "s.csv") and first is not second and len(calls) == 1
    ctx.files["ingest.stations"] = B   # the file changed: its stations, not the old ones
    assert steps._stations(ctx) == parse(B, "s.csv") and steps._stations(ctx)["CPH"].height_m == 31.0
    ctx.files["ingest.stations"] = BAD
    for _ in range(2):
        with pytest.raises(InputError, match="invalid station coordinate"):
            steps._stations(ctx)
    assert steps._stations(SimpleNamespace(files={}, paths={})) == {}
