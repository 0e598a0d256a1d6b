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
