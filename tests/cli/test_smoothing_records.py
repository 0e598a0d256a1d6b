"""Where ``smooth``'s per-fit records live (issue 14 item 5): inline in the metadata while small, else a
compact table (sidecar ``NAME.passes.parquet``, or a second Arrow stream after the table), read back
through :mod:`trackproc.io.smoothing_record` exactly as written.

Reference: the records ``smooth`` computed (its ``--summary``); the old inline layout still reads.
Before: 8,334 passes made a 975 MB file no command could read (Arrow's ~100 MB footer limit).
"""

from __future__ import annotations

import json

import pyarrow.parquet as pq
import pytest

from hostile import SAMPLE
from test_refine_cli import _simulate_trv
from test_smooth_cli import _table
from trackproc.io import smoothing_record
from trackproc.io.passfile import PassTable, parse_pass_table, pass_table_bytes, read_pass_table, write_pass_table
from trackproc.io.smoothing_record import find_fit_record, output_of, smoothing_of
from trackproc.pipeline.smooth import SmoothOptions, smooth

@pytest.fixture(scope="module")
def smoothed():
    """A smoothed table (3 fits) with its records in memory, as ``smooth`` makes it."""
    return smooth(_table(), SmoothOptions(degree=2, clip=None))


def _many(result, n: int) -> PassTable:
    """``n`` passes: the 3 real records copied under new pass ids (the samples stay those of 3 fits)."""
    fits = result.table.meta["smoothing"]["fits"]
    many = []
    for i in range(n):
        many.append({**fits[i % len(fits)], "pass_id": f"P{i:05d}"})
    meta = {**result.table.meta, "smoothing": {**result.table.meta["smoothing"], "fits": many}}
    return PassTable(result.table.frame, meta)


def test_few_records_stay_inline_and_read_back(smoothed, tmp_path):
    out = tmp_path / "s.parquet"
    write_pass_table(smoothed.table, str(out))
    assert not (tmp_path / "s.passes.parquet").exists()
    back = read_pass_table(str(out))
    assert list(smoothing_of(back.meta)["fits"]) == smoothed.summary["fits"]


@pytest.mark.slow
def test_ten_thousand_passes_read_back(smoothed, tmp_path):
    """10,000 fits: the footer keeps a pointer, the sidecar the records; every one reads back."""
    table = _many(smoothed, 10_000)
    fits = table.meta["smoothing"]["fits"]
    out = tmp_path / "many.parquet"
    write_pass_table(table, str(out))
    side = tmp_path / "many.passes.parquet"
    assert side.exists()
    footer = pq.ParquetFile(out).metadata.metadata[b"trackproc"]
    assert len(footer) < 64_000                                    # a pointer, not 10,000 records
    back = read_pass_table(str(out))
    records = smoothing_of(back.meta)["fits"]
    assert smoothing_of(back.meta)["records"]["count"] == len(records) == 10_000
    assert list(records) == fits                                   # every field of every record
    for i in (0, 4_321, 9_999):
        rec = fits[i]
        assert find_fit_record(back.meta, rec["station"], rec["pass_id"], rec["kind"]) == rec
    assert find_fit_record(back.meta, "DT", "nope", "doppler") is None
    # the same through a pipe: a second Arrow stream after the table
    data = pass_table_bytes(table, "arrow")
    piped = parse_pass_table(data, "<stdin>")
    assert smoothing_of(piped.meta)["records"]["in"] == "stream"
    assert list(smoothing_of(piped.meta)["fits"]) == fits


def test_old_inline_layout_still_reads(smoothed, tmp_path, monkeypatch):
    """A file written before the compact table (records inline however many) reads the same."""
    monkeypatch.setattr(smoothing_record, "INLINE_BYTES", 1 << 40)
    table = _many(smoothed, 50)
    out = tmp_path / "old.parquet"
    write_pass_table(table, str(out))
    assert b"coefficients" in pq.ParquetFile(out).metadata.metadata[b"trackproc"]
    back = read_pass_table(str(out))
    assert list(smoothing_of(back.meta)["fits"]) == table.meta["smoothing"]["fits"]


def test_sidecar_missing_or_foreign_is_an_input_error(smoothed, tmp_path, monkeypatch):
    from trackproc.errors import InputError

    monkeypatch.setattr(smoothing_record, "INLINE_BYTES", 0)
    out = tmp_path / "s.parquet"
    write_pass_table(smoothed.table, str(out))
    side = tmp_path / "s.passes.parquet"
    assert side.exists()
    write_pass_table(_many(smoothed, 4), str(tmp_path / "o.parquet"))
    (tmp_path / "o.passes.parquet").replace(side)                # the sidecar of another file
    table = read_pass_table(str(out))                            # the samples read without it
    with pytest.raises(InputError, match="does not belong"):
        find_fit_record(table.meta, "DT", "DT-001", "doppler")
    side.unlink()
    with pytest.raises(InputError, match="file not found"):
        list(smoothing_of(read_pass_table(str(out)).meta)["fits"])
    with pytest.raises(InputError, match="stdin does not carry"):
        find_fit_record(parse_pass_table(out.read_bytes(), "<stdin>").meta, "DT", "DT-001", "doppler")


@pytest.mark.slow
def test_cli_smooth_sidecar_and_pipe_feed_refine(run_cli, tmp_path, monkeypatch):
    """A few passes at the command line with the compact layout forced: smooth writes the sidecar
    (or the stream), and refine finds the same polynomial through either."""
    monkeypatch.setattr(smoothing_record, "INLINE_BYTES", 0)
    _simulate_trv(tmp_path, "--kinds", "doppler", "--carrier-hz", "2.2e9", "--sigma-doppler-hz", "0.1",
                  "--freq-offset-hz", "150", "--seed", "1")
    summary = tmp_path / "s.json"
    result = run_cli(["smooth", tmp_path / "pass.parquet", "--summary", summary, "-o", tmp_path / "s.parquet"])
    assert result.exit_code == 0, result.stderr
    assert (tmp_path / "s.passes.parquet").exists()
    fits = json.loads(summary.read_text())["fits"]
    back = read_pass_table(str(tmp_path / "s.parquet"))
    assert list(smoothing_of(back.meta)["fits"]) == fits and output_of(back.meta) == "samples"
    piped = run_cli(["smooth", tmp_path / "pass.parquet", "-o", "-"])
    assert piped.exit_code == 0, piped.stderr
    assert list(smoothing_of(parse_pass_table(piped.stdout_bytes, "<stdin>").meta)["fits"]) == fits

    outs = {}
    for name, args, data in (("file", [tmp_path / "s.parquet"], None), ("pipe", ["-"], piped.stdout_bytes)):
        refined = run_cli(["refine", *args, "--initial", SAMPLE / "stale.json", "--dut1", "0", "-q",
                           "-o", tmp_path / f"{name}.json"], input=data)
        assert refined.exit_code == 0, refined.stderr
        outs[name] = json.loads((tmp_path / f"{name}.json").read_text())
    assert outs["file"]["position_m"] == outs["pipe"]["position_m"]
    assert outs["file"]["diagnostics"]["traverse"]["curve"] == "metadata"
    # a pass file with a sidecar given on stdin: one line saying where the records are
    lost = run_cli(["refine", "-", "--initial", SAMPLE / "stale.json", "-q", "-o", tmp_path / "x.json"],
                   input=(tmp_path / "s.parquet").read_bytes())
    assert lost.exit_code == 2 and "s.passes.parquet" in lost.stderr and lost.stderr.count("\n") == 1
