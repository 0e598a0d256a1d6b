"""The one config file (issue 16): defaults for every command from TRACKPROC_CONFIG, with the
precedence flag > environment > file > built-in default, and typos rejected with the nearest name."""

from pathlib import Path

import pytest

from trackproc.cli.app import main
from trackproc.io.passfile import read_pass_table

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"


@pytest.fixture
def config(tmp_path, monkeypatch):
    path = tmp_path / "config.toml"
    (tmp_path / "st.csv").write_text((SAMPLE / "stations.csv").read_text())
    path.write_text('[defaults]\nstations = "st.csv"\ncarrier_hz = 2.2e9\n\n[ingest]\nmode = "one-way"\nformat = "csv"\n')
    monkeypatch.setenv("TRACKPROC_CONFIG", str(path))
    for key in ("CARRIER_HZ", "MODE", "STATIONS"):
        monkeypatch.delenv(f"TRACKPROC_{key}", raising=False)
    return path


def _ingest(tmp_path, *extra):
    out = tmp_path / "p.out"
    assert main(["-q", "ingest", str(SAMPLE / "doppler_pass.csv"), "-o", str(out), *extra]) == 0
    return out


def test_file_supplies_defaults_relative_to_itself(config, tmp_path):
    out = _ingest(tmp_path)
    assert out.read_text().startswith("# trackproc:")        # format = "csv" from [ingest]
    meta = read_pass_table(str(out)).meta
    assert meta["carrier_hz"] == 2.2e9 and meta["doppler_mode"] == "one-way"


def test_flag_beats_environment_beats_file(config, tmp_path, monkeypatch):
    monkeypatch.setenv("TRACKPROC_CARRIER_HZ", "2.3e9")
    assert read_pass_table(str(_ingest(tmp_path))).meta["carrier_hz"] == 2.3e9
    assert read_pass_table(str(_ingest(tmp_path, "--carrier-hz", "2.4e9"))).meta["carrier_hz"] == 2.4e9


@pytest.mark.parametrize("text,word", [("[refin]\nx = 1\n", "refine"), ("[ingest]\ncarier_hz = 1\n", "carrier_hz"),
                                       ("[defaults]\neopp = 'x'\n", "eop"), ("[ingest\n", "TOML")])
def test_typos_are_input_errors_naming_the_nearest(config, tmp_path, capsys, text, word):
    config.write_text(text)
    assert main(["ingest", str(SAMPLE / "doppler_pass.csv"), "-o", str(tmp_path / "x.parquet")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and word in err and str(config) in err
    assert not (tmp_path / "x.parquet").exists()
