"""Streaming ingest (issue 14 item 5): reading in chunks changes nothing a user sees.

The reference is the same command with chunks larger than the input (one chunk, the whole-file
read): with chunks of 1 to 7 rows every output byte, exit code and stderr line must be the
same, on inputs whose errors, duplicates, quoted newlines, comments and passes straddle chunk
boundaries. Peak memory on a large input is measured in a subprocess (slow).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hostile import DOPPLER_CSV, MULTI, STATIONS

ST = "station,lat_deg,lon_deg,height_m\nZHY,40.0,116.0,50\nKIR,67.8,20.9,400\n"


def _wide(n: int, *, bad: dict | None = None, station=lambda i: "ZHY", step=10) -> str:
    lines = ["time,station,range_m,elevation_deg"]
    for i in range(n):
        t = f"2026-03-20T09:{(i * step) // 60 % 60:02d}:{(i * step) % 60:02d}Z"
        cells = [t, station(i), f"{1.0e6 + i:.1f}", f"{10 + i * 0.1:.2f}"]
        for column, value in (bad or {}).get(i, {}).items():
            cells[column] = value
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


CASES = {
    "clean wide": (_wide(40), []),
    "two stations interleaved, gaps": (_wide(40, station=lambda i: "ZHY" if i % 3 else "KIR", step=200), []),
    "validation error late": (_wide(40, bad={25: {2: "-5"}}), []),
    "reader error after a validation error": (_wide(40, bad={5: {2: "-5"}, 30: {0: "yesterday"}}), []),
    "unknown station before a negative range": (_wide(40, bad={12: {1: "XXX"}, 20: {2: "-1"}}), []),
    "negative range before an unknown station": (_wide(40, bad={12: {2: "-1"}, 20: {1: "XXX"}}), []),
    "duplicate across chunks": (_wide(40, bad={33: {0: "2026-03-20T09:00:50Z"}}), []),
    "duplicate and unknown station": (_wide(40, bad={33: {0: "2026-03-20T09:00:50Z"}, 36: {1: "XXX"}}), []),
    "drop invalid": (_wide(40, bad={3: {2: "nan"}, 9: {3: "95"}, 15: {1: "XXX"}, 21: {0: "bad"},
                                    27: {0: "2026-03-20T09:00:10Z"}, 30: {2: "-2"}}), ["--drop-invalid"]),
    "wrong field count late": (_wide(40).replace("\n2026-03-20T09:05:00Z,ZHY,", "\n2026-03-20T09:05:00Z,ZHY,1,"), []),
    "long layout with sigma and pass ids": (
        "# a comment line\ntime,station,kind,value,sigma,pass_id\n"
        + "".join(f"2026-03-20T09:30:{i:02d}Z,ZHY,{'range_km' if i % 2 else 'elevation_deg'},{10 + i},,"
                  f"{'mine' if i > 30 else ''}\n\n" for i in range(45)), []),
    "spaces, tabs, no final newline": (_wide(30).replace(",ZHY,", " ,  ZHY\t, ").rstrip("\n"), []),
    "comma-only and blank lines late": (_wide(30, bad={25: {2: "-1"}}).replace("\n2026-03-20T09:04:00Z", "\n,,,\n \n2026-03-20T09:04:00Z"),
                                        []),
    "a 200 kB cell late": (_wide(30).replace("\n2026-03-20T09:04:00Z,ZHY,", "\n2026-03-20T09:04:00Z,ZHY" + "x" * 200_000
                                             + ","), []),
    "quoted newlines and comments": (
        'time,station,"range_m",elevation_deg\n'
        + "".join(f'2026-03-20T09:30:{i:02d}Z,ZHY,"{1e6 + i}\n",{10 + i * 0.1}\n# note {i}\n' for i in range(20))
        + '2026-03-20T09:31:00Z,ZHY,"-1\n",10\n', []),
}


#: (exit code, stderr) of the runs so far by (input, options, chunk, format): test_cases_fail_where_they_should
#: reads the chunk-2 Parquet runs test_chunks_change_nothing made of half of the cases (ingest is
#: deterministic; the stderr holds no path, the folder replaced by ``<dir>``; the output file does)
_OUTCOMES: dict = {}


def _outcome(run_cli, monkeypatch, tmp_path, name, text, extra, chunk, fmt):
    """``_run``'s exit code and stderr, read from an earlier run of the same input when there was one."""
    key = (text, tuple(extra), chunk, fmt)
    if key not in _OUTCOMES:
        _run(run_cli, monkeypatch, tmp_path, name, text, extra, chunk, fmt)
    return _OUTCOMES[key]


def _run(run_cli, monkeypatch, tmp_path, name, text, extra, chunk, fmt):
    folder = tmp_path / "work"       # one folder: the paths in the metadata are the same
    folder.mkdir(exist_ok=True)
    raw = folder / "in.csv"
    raw.write_text(text)
    stations = folder / "st.csv"
    stations.write_text(ST)
    if chunk is None:
        monkeypatch.delenv("TRACKPROC_CHUNK_ROWS", raising=False)
    else:
        monkeypatch.setenv("TRACKPROC_CHUNK_ROWS", str(chunk))
    out = folder / f"out.{fmt}"
    if out.exists():
        out.unlink()
    result = run_cli(["ingest", raw, "--stations", stations, *extra, "-o", out])
    data = out.read_bytes() if out.exists() else None
    _OUTCOMES[(text, tuple(extra), chunk, fmt)] = (result.exit_code, result.stderr.replace(str(folder), "<dir>"))
    return result.exit_code, result.stderr.replace(str(folder), "<dir>"), data


@pytest.mark.parametrize("name", sorted(CASES))
def test_chunks_change_nothing(run_cli, monkeypatch, tmp_path, name):
    text, extra = CASES[name]
    fmt = "parquet" if len(name) % 2 else "csv"
    whole = _run(run_cli, monkeypatch, tmp_path, name, text, extra, None, fmt)
    for chunk in (2, 3, 7):
        assert _run(run_cli, monkeypatch, tmp_path, name, text, extra, chunk, fmt) == whole, (name, chunk)


def test_cases_fail_where_they_should(run_cli, monkeypatch, tmp_path):
    """The cases above are what their names say (so the comparison covers errors, not only successes)."""
    codes = {name: _outcome(run_cli, monkeypatch, tmp_path, name, text, extra, 2, "parquet")
             for name, (text, extra) in CASES.items()}
    assert codes["clean wide"][0] == 0 and codes["drop invalid"][0] == 0
    assert "row 27" in codes["validation error late"][1] and "negative range" in codes["validation error late"][1]
    assert "row 32" in codes["reader error after a validation error"][1]        # readers run first
    assert "row 14" in codes["unknown station before a negative range"][1]
    assert "row 14" in codes["negative range before an unknown station"][1]
    assert "row 35" in codes["duplicate across chunks"][1] and "first at" in codes["duplicate across chunks"][1]
    assert "row 35" in codes["duplicate and unknown station"][1]
    assert "wrong number of fields" in codes["wrong field count late"][1]
    assert codes["long layout with sigma and pass ids"][0] == 0
    assert codes["spaces, tabs, no final newline"][0] == 0
    assert "row 29" in codes["comma-only and blank lines late"][1]
    assert "unreadable CSV" in codes["a 200 kB cell late"][1] and "row 26" in codes["a 200 kB cell late"][1]   # data row 27 after two skipped lines
    assert "row 62" in codes["quoted newlines and comments"][1]   # 20 x 3 lines after the header
    assert ("dropped 9 invalid samples: unparseable time 2, non-finite value 1, elevation out of range 1, "
            "negative range 1, unknown station 2, duplicated timestamp 2") in codes["drop invalid"][1]


@pytest.mark.parametrize("source", [DOPPLER_CSV, MULTI], ids=["csv", "parquet"])
@pytest.mark.parametrize("fmt", ["parquet", "arrow", "csv"])
def test_sample_inputs_byte_identical_across_chunks(run_cli, monkeypatch, tmp_path, source, fmt):
    outputs = []
    for chunk in (None, 97, 1000):
        if chunk is None:
            monkeypatch.delenv("TRACKPROC_CHUNK_ROWS", raising=False)
        else:
            monkeypatch.setenv("TRACKPROC_CHUNK_ROWS", str(chunk))
        result = run_cli(["ingest", source, "--stations", STATIONS, "--carrier-hz", "2.2e9", "--mode", "one-way",
                          "--format", fmt, "-o", "-"])
        assert result.exit_code == 0, result.stderr
        outputs.append(result.stdout_bytes)
    assert outputs[0] == outputs[1] == outputs[2]


def test_stdin_streams_too(run_cli, monkeypatch, tmp_path):
    monkeypatch.setenv("TRACKPROC_CHUNK_ROWS", "50")
    via_file = run_cli(["ingest", DOPPLER_CSV, "--stations", STATIONS, "--carrier-hz", "2.2e9", "--mode", "one-way",
                        "-o", "-"])
    via_pipe = run_cli(["ingest", "-", "--stations", STATIONS, "--carrier-hz", "2.2e9", "--mode", "one-way",
                        "-o", "-"], input=DOPPLER_CSV.read_bytes())
    assert via_file.exit_code == via_pipe.exit_code == 0
    import pyarrow as pa

    tables = [pa.ipc.open_stream(r.stdout_bytes).read_all() for r in (via_file, via_pipe)]
    assert tables[0].num_rows == 650 and tables[0].equals(tables[1])   # the metadata differs: sources


def _big_csv(path: Path, n: int) -> None:
    t0 = np.datetime64("2026-03-20T09:00:00", "ms")
    with open(path, "w") as handle:
        handle.write("time,station,range_m\n")
        for start in range(0, n, 200_000):
            stop = min(n, start + 200_000)
            times = np.datetime_as_string(t0 + np.arange(start, stop) * np.timedelta64(100, "ms"), unit="ms")
            handle.write("".join(f"{t}Z,ZHY,{1e6 + i % 1000:.1f}\n" for i, t in enumerate(times)))


@pytest.mark.slow
@pytest.mark.subprocess
def test_peak_memory_of_a_large_ingest(tmp_path):
    """5e5 rows (21 MB of CSV) ingest within 400 MB of peak RSS; before streaming it took ~0.45 GB
    and grew by ~0.85 kB a row (1e6 rows: 0.86 GB), now by ~50 bytes (benchmarks/ingest_memory.py)."""
    raw, out, stations = tmp_path / "big.csv", tmp_path / "big.parquet", tmp_path / "st.csv"
    _big_csv(raw, 500_000)
    stations.write_text(ST)
    exe = str(Path(sys.executable).with_name("trackproc"))
    wrapper = ("import resource, subprocess, sys; p = subprocess.run(sys.argv[1:]); "
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, p.returncode)")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "src")}
    done = subprocess.run([sys.executable, "-c", wrapper, exe, "ingest", str(raw), "--stations", str(stations),
                           "-q", "-o", str(out)], capture_output=True, text=True, env=env, check=True)
    kb, code = done.stdout.split()
    assert int(code) == 0, done.stderr
    assert int(kb) / 1024 < 400, f"peak RSS {int(kb) / 1024:.0f} MB"
    import pyarrow.parquet as pq

    assert pq.ParquetFile(out).metadata.num_rows == 500_000


def test_samples_of_all_inputs_are_bounded(run_cli, monkeypatch, tmp_path):
    """The samples kept for the whole-set checks are bounded too (a wide row gives several)."""
    raw, stations = tmp_path / "in.csv", tmp_path / "st.csv"
    raw.write_text(_wide(8))                       # 8 rows, 16 samples
    stations.write_text(ST)
    monkeypatch.setenv("TRACKPROC_MAX_INPUT_ROWS", "10")
    monkeypatch.setenv("TRACKPROC_CHUNK_ROWS", "3")
    result = run_cli(["ingest", raw, "--stations", stations, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and "more than 10 samples" in result.stderr
    assert result.stderr.count("\n") == 1 and not (tmp_path / "o.parquet").exists()


@pytest.mark.parametrize("fmt", ["parquet", "arrow", "csv"])
def test_streamed_writer_gives_the_whole_table_writers_bytes(run_cli, tmp_path, fmt):
    """``ingest`` writes slice by slice; the in-memory path (read_raw, ingest, write_pass_table) is the reference."""
    from trackproc.io.passfile import write_pass_table
    from trackproc.io.stations import read_stations
    from trackproc.io.tabular import read_raw
    from trackproc.pipeline.ingest import IngestOptions, ingest

    out, ref = tmp_path / f"o.{fmt}", tmp_path / f"r.{fmt}"
    result = run_cli(["ingest", MULTI, "--stations", STATIONS, "--carrier-hz", "2.2e9", "--mode", "one-way",
                      "--format", fmt, "-o", out])
    assert result.exit_code == 0, result.stderr
    table = ingest([read_raw(str(MULTI))], read_stations(str(STATIONS)),
                   IngestOptions(carrier_hz=2.2e9, doppler_mode="one-way")).table
    write_pass_table(table, str(ref), fmt)
    assert out.read_bytes() == ref.read_bytes()


def _random_csv(rng) -> str:
    """Rows of a wide CSV mixed with what the chunk cutter must get right: comment lines holding
    quotes, blank lines, quoted cells across lines, invalid cells, repeated times, unknown stations."""
    lines = ["time,station,range_m,elevation_deg"]
    for i in range(int(rng.integers(5, 40))):
        roll = rng.random()
        t = f"2026-03-20T09:{i // 6:02d}:{(i % 6) * 10:02d}Z"
        if roll < 0.08:
            lines.append('# a comment with a "quote')
        elif roll < 0.14:
            lines.append("")
        elif roll < 0.2:
            lines.append(f'{t},ZHY,"{1e6 + i}\n",{10 + i * 0.1:.1f}')
        elif roll < 0.24:
            lines.append(f"{t},ZHY,{-i},{10:.1f}")
        elif roll < 0.27:
            lines.append(f"2026-03-20T09:00:00Z,ZHY,{1e6},{10:.1f}")
        elif roll < 0.29:
            lines.append(f"{t},XYZ,{1e6},{10:.1f}")
        elif roll < 0.31:
            lines.append(f"{t},ZHY,abc,")
        else:
            lines.append(f"{t},{'ZHY' if rng.random() < 0.7 else 'KIR'},{1e6 + i},{10 + i * 0.1:.1f}")
    return "\n".join(lines) + ("\n" if rng.random() < 0.8 else "")


@pytest.mark.parametrize("seed", range(12))
def test_random_inputs_same_across_chunks(run_cli, monkeypatch, tmp_path, seed):
    rng = np.random.default_rng(seed)
    text = _random_csv(rng)
    extra = ["--drop-invalid"] if seed % 3 == 0 else []
    whole = _run(run_cli, monkeypatch, tmp_path, "random", text, extra, None, "csv")
    for chunk in rng.integers(1, 6, size=2):
        assert _run(run_cli, monkeypatch, tmp_path, "random", text, extra, int(chunk), "csv") == whole, (seed, chunk)
