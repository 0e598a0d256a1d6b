"""ingest's table handed on as numpy columns (Samples.numpy_columns) gives every column as the
DataFrame it replaces gives it (PassTable.column of Samples.frame): dtypes, values, str names."""

from pathlib import Path

import numpy as np

from trackproc.io.stations import read_stations
from trackproc.io.tabular import read_raw
from trackproc.pipeline.ingest import IngestOptions, ingest
from trackproc.types.passes import PassTable

ROOT = Path(__file__).resolve().parents[2]


def _same(a, b):
    if a.dtype != b.dtype:
        return False
    if a.dtype == object:
        return list(a) == list(b) and all(type(x) is type(y) for x, y in zip(a, b))
    return np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def test_numpy_columns_are_the_frames_columns():
    stations = read_stations(str(ROOT / "sample_data" / "stations.csv"))
    for name, options in (("doppler_pass.csv", IngestOptions(carrier_hz=2.2e9, doppler_mode="one-way")),
                          ("elevation_pass.csv", IngestOptions()), ("multistation.parquet", IngestOptions())):
        result = ingest([read_raw(str(ROOT / "sample_data" / name))], stations, options)
        table = result.table
        assert table.numpy_columns() is not None          # no DataFrame built on the way
        reference = PassTable(result.samples.frame(), result.meta)
        assert table.column_names == reference.column_names
        for column in reference.column_names:
            assert _same(table.column(column), reference.column(column)), (name, column)
        assert table.frame.equals(reference.frame)        # and the frame, when asked for, is the same


def test_a_frame_changed_in_place_is_what_is_read_and_written(tmp_path):
    """A caller that reads ``frame`` and changes it in place (a renamed station) gets its change
    into every later read (``column``) and write (the pass file), for a table of numpy columns and
    for a reader's arrays alike."""
    from trackproc.io.passfile import read_pass_table, write_pass_table

    stations = read_stations(str(ROOT / "sample_data" / "stations.csv"))
    raw = read_raw(str(ROOT / "sample_data" / "elevation_pass.csv"))
    name = str(raw.frame["station"].iloc[0])
    raw.frame["station"] = raw.frame["station"].replace(name, "XXX")
    assert set(ingest([raw], {**stations, "XXX": stations[name]}, IngestOptions()).table.column("station")) == {"XXX"}

    table = ingest([read_raw(str(ROOT / "sample_data" / "elevation_pass.csv"))], stations, IngestOptions()).table
    table.frame["station"] = table.frame["station"].replace(name, "YYY")
    assert set(table.column("station")) == {"YYY"}
    write_pass_table(table, str(tmp_path / "p.parquet"))
    assert set(read_pass_table(str(tmp_path / "p.parquet")).column("station")) == {"YYY"}
