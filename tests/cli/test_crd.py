"""ILRS CRD reader: v1 and v2 normal points -> two-way ranges at ground reception; errors.

References: the ILRS CRD v1.01/v2.01 record layouts; the real LAGEOS-2 file of
../shared/realdata/orekit-lageos2 (95 normal points of 4 stations, README).
"""

import numpy as np
import pandas as pd
import pytest

from trackproc.constants import C_LIGHT
from trackproc.errors import InputError
from trackproc.io.crd import looks_like_crd, read_crd
from trackproc.io.tabular import detect_layout

from realdata import REALDATA

V1 = """h1 CRD  1 2016  2 13 23
h2 YARL       7090  5 13 3
h3 lageos2     9207002 5986    22195 0 1
h4  1 2016  2 13 23 50  0 2016  2 14  0 10  0  0 0 0 0 1 0 2 0
c0 0  532.000 std la1 mcp ti1
20 85900.001  983.70 301.40  24. 0
11 85900.000000000000     0.039237325685 std 2  120.0     94   57.0   0.183  -0.536      -1.0  15.67 0
20   300.001  983.90 301.00  28. 0
11   300.000000000000     0.040000000000 std 0  120.0     39   65.0   0.083  -0.301      -1.0   6.50 0
h8
h9
"""

V2 = """H1 CRD  2 2021 06 01 10
H2 MATM 7941 77 1 4 ILRS
H3 lageos2 9207002 5986 22195 0 1 1
H4 1 2021 06 01 10 00 00 2021 06 01 10 30 00 0 0 0 0 1 0 2 0
H5 1 21 060110 HTS 12001
C0 0 1064.000 std la1 mcp ti1
20 36010.000 1000.10 290.00 55.0 0
11 36010.250000000000 0.045000000000 std 1 120.0 100 20.0 0.0 0.0 -1.0 10.0 0 3.5
H8
H9
"""


def test_v1_times_are_ground_reception_and_values_one_way_equivalent():
    raw = read_crd(V1.encode(), "v1.npt")
    f = raw.frame
    assert list(f["kind"]) == ["range", "range"] and list(f["station"]) == ["7090", "7090"]
    tof = 0.039237325685
    t0 = pd.Timestamp("2016-02-13T00:00:00Z") + pd.Timedelta(seconds=85900) + pd.Timedelta(seconds=tof)
    assert abs((f["time"].iloc[0] - t0).value) <= 1                       # epoch event 2: transmit + tof
    assert f["time"].iloc[1] == pd.Timestamp("2016-02-14T00:05:00Z")      # event 0, after midnight: next day
    assert f["value"].iloc[0] == pytest.approx(C_LIGHT * tof / 2, abs=1e-9)
    assert raw.meta["doppler_mode"] == "two-way"
    crd = raw.meta["crd"]
    assert crd["version"] == 1 and crd["sessions"][0]["wavelength_nm"] == 532.0
    assert crd["meteo"]["7090"]["time"][1].startswith("2016-02-14T00:05:00.001")


def test_v2_bounce_epoch_and_wavelength():
    raw = read_crd(V2.encode(), "v2.crd")
    t = raw.frame["time"].iloc[0]
    expect = pd.Timestamp("2021-06-01T10:00:10.250Z") + pd.Timedelta(seconds=0.0225)   # bounce + tof/2
    assert abs((t - expect).value) <= 1
    assert raw.meta["crd"]["sessions"][0]["wavelength_nm"] == 1064.0
    assert raw.frame["station"].iloc[0] == "7941"


def test_sniffed_by_content_and_suffix():
    assert looks_like_crd(V1) and looks_like_crd(V2) and not looks_like_crd("time,range\n")
    assert detect_layout(V1.encode(), "anything.txt") == "crd"
    assert detect_layout(b"h1 crd 1 2016 2 13 23\n", "x") == "crd"


def test_meteo_records_in_the_metadata():
    meteo = read_crd(V1.encode(), "v1.npt").meta["crd"]["meteo"]["7090"]
    assert meteo["pressure_hpa"] == [983.7, 983.9] and meteo["temperature_k"] == [301.4, 301.0]
    assert meteo["humidity_percent"] == [24.0, 28.0] and meteo["time"][0].startswith("2016-02-13T23:51:40.001")


@pytest.mark.parametrize("edit, field", [
    (("0.039237325685", "-0.0392"), "time of flight"),
    (("0.039237325685", "abc"), "time of flight"),
    ((" 0 0 0 0 1 0 2 0", " 0 0 0 0 1 0 1 0"), "range type"),
    (("std 2  120.0     94", "std 4  120.0     94"), "epoch event"),
    (("5 13 3", "5 13 1"), "time scale"),
    (("h1 CRD  1", "h1 CRD  3"), "format version"),
])
def test_bad_records_fail_with_one_line_naming_row_and_field(edit, field):
    text = V1.replace(*edit)
    with pytest.raises(InputError) as err:
        read_crd(text.encode(), "bad.npt")
    message = str(err.value)
    assert "bad.npt" in message and field in message and "\n" not in message


def test_data_before_headers_is_refused():
    with pytest.raises(InputError, match="before the H1 header"):
        read_crd(b"11 300.0 0.04 std 2 120 1 1 0 0 -1 1 0\n", "x.npt")
    with pytest.raises(InputError, match="H2/H4"):
        read_crd(b"h1 CRD 1 2016 2 13 1\n11 300.0 0.04 std 2 120 1 1 0 0 -1 1 0\n", "x.npt")


LAGEOS = REALDATA / "orekit-lageos2" / "lageos2_20160214.npt"


@pytest.mark.realdata
@pytest.mark.skipif(not LAGEOS.exists(), reason="real data not available")
def test_real_lageos2_file():
    raw = read_crd(LAGEOS.read_bytes(), str(LAGEOS))
    f = raw.frame
    assert len(f) == 95
    assert sorted(f["station"].unique()) == ["7090", "7119", "7825", "7941"]
    # LAGEOS-2 ranges: 5 900 to 9 000 km above 20 deg elevation
    assert f["value"].between(5.5e6, 1.0e7).all()
    assert f["time"].min() >= pd.Timestamp("2016-02-11T13:07:00Z")
    assert f["time"].max() <= pd.Timestamp("2016-02-14T07:38:00Z")
    assert len(raw.meta["crd"]["sessions"]) == 11          # 11 H4 session headers


def test_cli_ingest_of_crd_with_sinex_stations_and_a_bad_record(run_cli, write):
    from test_sinex import SNX

    npt = write("v1.npt", V1)
    snx = write("s.snx", SNX)
    out = write("dummy", "").parent / "p.csv"
    r = run_cli(["ingest", npt, "--stations", snx, "-o", out])
    assert r.exit_code == 0, r.stderr
    from trackproc.io.csvtext import parse_csv_metadata

    text = out.read_text()
    meta = parse_csv_metadata(line[1:] for line in text.splitlines() if line.startswith("#"))
    assert "7090-20160213T2350" in text and meta["doppler_mode"] == "two-way"
    bad = write("bad.npt", V1.replace("0.039237325685", "1.5"))
    r = run_cli(["ingest", bad, "--stations", snx, "-o", out])
    assert r.exit_code == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "bad.npt, row 7" in r.stderr and "time of flight" in r.stderr


def test_normal_point_sigma_is_its_own_precision():
    """sigma = c/2 · rms / √n of record 11 (bin RMS 57 ps two-way of 94 raw ranges: 0.88 mm one-way)."""
    f = read_crd(V1.encode(), "v1.npt").frame
    assert f["sigma"].iloc[0] == pytest.approx(C_LIGHT / 2 * 57.0e-12 / np.sqrt(94), rel=1e-12)
    assert f["sigma"].iloc[1] == pytest.approx(C_LIGHT / 2 * 65.0e-12 / np.sqrt(39), rel=1e-12)
    assert 0.8e-3 < f["sigma"].iloc[0] < 0.9e-3


@pytest.mark.parametrize("option, expected", [([], None), (["--sigma-range-m", "0.3"], 0.3)])
def test_ingest_keeps_the_crd_sigma_unless_told(run_cli, tmp_path, option, expected):
    npt, stations, out = tmp_path / "v1.npt", tmp_path / "st.csv", tmp_path / "p.parquet"
    npt.write_text(V1)
    stations.write_text("station,lat_deg,lon_deg,height_m\n7090,-29.0465,115.3467,244\n")
    r = run_cli(["ingest", npt, "--stations", stations, "-o", out, *option])
    assert r.exit_code == 0, r.stderr
    sigma = pd.read_parquet(out)["sigma"].to_numpy()
    want = read_crd(V1.encode(), "v1.npt").frame["sigma"].to_numpy() if expected is None else np.full(2, expected)
    np.testing.assert_allclose(np.sort(sigma), np.sort(want), rtol=1e-12)
