"""``trackproc info``: summary of a pass file as text or JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from trackproc.io.passfile import PassTable, base_meta, write_pass_table
from trackproc.pipeline.info import format_info, info_dict, summarize


def _table() -> PassTable:
    t0 = pd.Timestamp("2026-03-20T09:30:00Z")
    rows = []
    for k, s in enumerate((0, 10, 20)):       # pass A-001: 20 s, elevation up to 30 deg
        rows.append((t0 + pd.Timedelta(seconds=s), "A", "A-001", "elevation", math.radians(10 * (k + 1)), 1e-4))
        rows.append((t0 + pd.Timedelta(seconds=s), "A", "A-001", "range_rate", -100.0 * k, 0.1))
    rows.append((t0 + pd.Timedelta(seconds=3600), "A", "A-002", "range_rate", 5.0, 0.1))
    rows.append((t0 + pd.Timedelta(seconds=5), "B", "B-001", "doppler", -1e3, 1.0))
    rows.append((t0 + pd.Timedelta(seconds=65.5), "B", "B-001", "doppler", -2e3, 1.0))
    frame = pd.DataFrame(rows, columns=["time", "station", "pass_id", "kind", "value", "sigma"])
    frame["time"] = frame["time"].dt.as_unit("ns")
    meta = base_meta(carrier_hz=2.2e9, doppler_mode="one-way", sources=["raw.csv"],
                     stations={"A": {"lat_deg": 1.0, "lon_deg": 2.0, "height_m": 3.0}})
    return PassTable(frame, meta)


def test_summary_counts_durations_and_max_elevation():
    info = summarize(_table(), "p.parquet")
    assert info.samples == 9
    assert info.kinds == {"range_rate": 4, "doppler": 2, "elevation": 3}
    assert [(p.pass_id, p.duration_s) for p in info.passes] == [("A-001", 20.0), ("A-002", 0.0), ("B-001", 60.5)]
    first = info.passes[0]
    assert first.samples == {"range_rate": 3, "elevation": 3}
    assert math.isclose(first.max_elevation_deg, 30.0)
    assert info.passes[2].max_elevation_deg is None
    assert first.start == "2026-03-20T09:30:00.000Z" and first.end == "2026-03-20T09:30:20.000Z"
    stations = {s.name: s for s in info.stations}
    assert stations["A"].passes == 2 and stations["A"].samples == 7 and stations["A"].height_m == 3.0
    assert stations["B"].lat_deg is None          # not in the metadata
    assert (info.carrier_hz, info.doppler_mode) == (2.2e9, "one-way")


def test_text_table_is_aligned_and_json_is_complete():
    info = summarize(_table(), "p.parquet")
    text = format_info(info)
    lines = text.splitlines()
    header = next(line for line in lines if line.startswith("pass_id"))
    assert "max_elev_deg" in header and "duration_s" in header
    table = lines[lines.index(header):]
    assert len({len(line) for line in table}) == 1               # right-aligned numbers line up
    assert all(line.startswith(("A-00", "B-00")) for line in table[1:])
    assert "2200000000.0 Hz, Doppler mode one-way" in text
    data = json.loads(json.dumps(info_dict(info)))
    assert abs(data["passes"][0]["max_elevation_deg"] - 30.0) < 1e-9
    assert set(data) >= {"stations", "passes", "kinds", "carrier_hz", "doppler_mode", "start", "end"}


def test_info_cli_text_json_and_stdin(run_cli, tmp_path):
    path = tmp_path / "p.parquet"
    write_pass_table(_table(), str(path), "parquet")
    text = run_cli(["info", path])
    assert text.exit_code == 0 and "A-001" in text.stdout and text.stderr == ""
    as_json = run_cli(["info", path, "--json"])
    assert json.loads(as_json.stdout)["samples"] == 9
    arrow = tmp_path / "p.arrow"
    write_pass_table(_table(), str(arrow), "arrow")
    piped = run_cli(["info", "-", "--json"], input=arrow.read_bytes())
    assert piped.exit_code == 0 and json.loads(piped.stdout)["source"] == "<stdin>"
    csv_path = tmp_path / "p.csv"
    write_pass_table(_table(), str(csv_path), "csv")
    from_csv = json.loads(run_cli(["info", csv_path, "--json"]).stdout)
    assert from_csv["passes"] == json.loads(as_json.stdout)["passes"]


def test_info_lists_extra_columns():
    table = _table()
    table.frame["flag"] = np.zeros(len(table.frame), dtype=bool)
    assert summarize(table, "s").extra_columns == ["flag"]
    assert "columns +   flag" in format_info(summarize(table, "s"))


def test_info_summarises_an_ephemeris_from_propagate(tmp_path):
    import json as _json

    from typer.testing import CliRunner

    from trackproc.cli.app import _register, app

    _register()
    root = Path(__file__).resolve().parents[2]
    runner = CliRunner()
    eph = tmp_path / "eph.parquet"
    out = runner.invoke(app, ["propagate", str(root / "sample_data" / "truth.json"), "--span", "6000",
                              "--step", "60", "-o", str(eph)])
    assert out.exit_code == 0, out.output
    res = runner.invoke(app, ["info", str(eph), "--json"])
    assert res.exit_code == 0, res.output
    summary = _json.loads(res.stdout)
    assert summary["samples"] == 101 and summary["step_s"] == 60.0
    # |r| starts at the seed 004 Table 1 truth, 7191.0 km
    assert abs(summary["radius_km"][0] - 7191.0) < 0.01
