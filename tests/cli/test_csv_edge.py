"""The CSV edge is for people (issue 16): angles in degrees (kind ``elevation_deg``), radians kept
in Parquet; a CSV read back is the same table; ``--no-metadata`` gives plain CSV that pandas reads
without options."""

from pathlib import Path

import numpy as np
import pandas as pd

from trackproc.cli.app import main
from trackproc.io.passfile import read_pass_table

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"


def _smooth(tmp_path, out, *extra):
    passfile = tmp_path / "el.parquet"
    assert main(["-q", "ingest", str(SAMPLE / "elevation_pass.csv"), "--stations", str(SAMPLE / "stations.csv"),
                 "-o", str(passfile)]) == 0
    assert main(["-q", *extra, "smooth", str(passfile), "-o", str(out)]) == 0


def test_angles_in_degrees_in_csv_and_back(tmp_path):
    _smooth(tmp_path, tmp_path / "s.parquet")
    _smooth(tmp_path, tmp_path / "s.csv")
    radians = read_pass_table(str(tmp_path / "s.parquet")).frame
    text = (tmp_path / "s.csv").read_text().splitlines()
    assert text[0].startswith("# trackproc:")
    raw = pd.read_csv(tmp_path / "s.csv", comment="#")
    assert set(raw["kind"]) == {"elevation_deg", "azimuth_deg"}
    # the file's own elevations, in degrees, against the shipped input (degrees)
    shipped = pd.read_csv(SAMPLE / "elevation_pass.csv")
    el = raw[raw["kind"] == "elevation_deg"]["value"].to_numpy()
    assert np.allclose(np.sort(el), np.sort(shipped["elevation_deg"].to_numpy()), atol=1e-9)
    back = read_pass_table(str(tmp_path / "s.csv")).frame
    assert list(back["kind"]) == list(radians["kind"])
    for column in ("value", "sigma", "smoothed", "residual"):
        assert np.allclose(back[column], radians[column], rtol=1e-12, atol=2e-14)   # 1e-12 deg rounding


def test_no_metadata_gives_plain_csv(tmp_path, monkeypatch):
    monkeypatch.setenv("TRACKPROC_CSV_METADATA", "1")   # undone after the test (main sets it to 0)
    _smooth(tmp_path, tmp_path / "plain.csv", "--no-metadata")
    first = (tmp_path / "plain.csv").read_text().splitlines()[0]
    assert first.startswith("time,station,pass_id,kind,value,sigma")
    frame = pd.read_csv(tmp_path / "plain.csv")
    assert len(frame) == 608 and frame["value"].notna().all()


def test_csv_metadata_is_a_readable_block_read_back_whole(tmp_path):
    """The metadata opening a CSV output is a block of short lines (one key a line; only a single
    long string may exceed the width), the same dict as the Parquet output's metadata when read
    back by trackproc, skipped by pandas ``comment="#"``; the one-line form of earlier versions
    still reads."""
    import json

    from trackproc.io.csvtext import META_WIDTH, parse_csv_metadata

    _smooth(tmp_path, tmp_path / "s.parquet")
    _smooth(tmp_path, tmp_path / "s.csv")
    lines = (tmp_path / "s.csv").read_text().splitlines()
    block = [line for line in lines if line.startswith("#")]
    assert block[0] == "# trackproc: {" and block[-1] == "# }" and len(block) > 10
    assert lines.index(block[-1]) == len(block) - 1                  # the block, then the header
    for line in block:
        assert len(line) <= META_WIDTH + 2 or line.count('"') == 4, line   # "key": "one long string"
    meta = read_pass_table(str(tmp_path / "s.parquet")).meta
    csv_meta = parse_csv_metadata(line[1:] for line in block)
    meta.pop("smoothing", None), csv_meta.pop("smoothing", None)     # its record pointers differ by format
    assert csv_meta == json.loads(json.dumps(meta, default=str))
    assert len(pd.read_csv(tmp_path / "s.csv", comment="#")) == 608
    one_line = "# trackproc: " + json.dumps(csv_meta, separators=(",", ":"))
    old = tmp_path / "old.csv"
    old.write_text("\n".join([one_line] + lines[len(block):]) + "\n")
    assert read_pass_table(str(old)).meta["stations"] == read_pass_table(str(tmp_path / "s.csv")).meta["stations"]


def test_no_metadata_gives_plain_residual_csv(tmp_path, monkeypatch):
    """Residual CSVs (compare -o, estimate --residuals) honour --no-metadata as every CSV output does."""
    monkeypatch.setenv("TRACKPROC_CSV_METADATA", "1")
    args = ["compare", str(SAMPLE / "multistation.parquet"), str(SAMPLE / "truth_at_start.json"), "--remove", "none"]
    assert main(["-q", *args, "-o", str(tmp_path / "meta.csv")]) == 0
    assert main(["-q", "--no-metadata", *args, "-o", str(tmp_path / "plain.csv")]) == 0
    assert (tmp_path / "meta.csv").read_text().startswith("# trackproc: {\n")
    plain = (tmp_path / "plain.csv").read_text()
    assert plain.startswith("time,station,pass_id,kind,unit,observed,computed,residual")
    assert pd.read_csv(tmp_path / "plain.csv").equals(pd.read_csv(tmp_path / "meta.csv", comment="#"))
