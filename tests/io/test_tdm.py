"""CCSDS TDM (KVN) reader: values in SI units and UTC, conventions, and every input error with
its file, line and keyword."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackproc.constants import C_LIGHT
from trackproc.errors import EXIT_INPUT, InputError
from trackproc.io.tdm import read_tdm

DATA = Path(__file__).resolve().parents[1] / "data" / "tdm"


def load(name: str, **kwargs):
    path = DATA / name
    return read_tdm(path.read_bytes(), str(path), **kwargs)


def utc(text: str) -> pd.Timestamp:
    return pd.Timestamp(text, tz="UTC")


def tdm(*lines: str) -> bytes:
    """A TDM from lines: line i of the tuple is row i + 1 of the file."""
    return ("\n".join(lines) + "\n").encode()


HEADER = ("CCSDS_TDM_VERS = 2.0", "CREATION_DATE = 2020-01-01T00:00:00", "ORIGINATOR = TEST")


def meta(*extra: str, path: str = "2,1", time_system: str = "UTC") -> tuple:
    lines = ["META_START", f"TIME_SYSTEM = {time_system}", "PARTICIPANT_1 = STA",
             "PARTICIPANT_2 = SAT"]
    if path:
        lines.append(f"PATH = {path}")
    return (*lines, *extra, "META_STOP")


def read_error(data: bytes, **kwargs) -> InputError:
    with pytest.raises(InputError) as info:
        read_tdm(data, "bad.tdm", **kwargs)
    err = info.value
    assert err.file == "bad.tdm"
    assert err.exit_code == EXIT_INPUT
    return err


# ---------------------------------------------------------------------------------- fixtures


def test_one_way_receive_freq_and_doppler_instantaneous():
    raw = load("oneway_doppler.tdm")
    f = raw.frame
    assert list(f.columns) == ["time", "station", "kind", "value", "sigma", "row", "unit"]
    assert str(f["time"].dtype) == "datetime64[ns, UTC]"
    assert set(f["station"]) == {"DSS-25"}          # PATH 2,1: the receiver, participant 1
    assert f["sigma"].isna().all()

    dop = f[f["kind"] == "doppler"]
    # received = FREQ_OFFSET + value; doppler = received - TRANSMIT_FREQ_2 (the transmitter)
    tx = 32021035600.0
    expected = [32021035200.0 + v - tx for v in (-409.2735, -371.1568, -333.0551)]
    np.testing.assert_allclose(dop["value"], expected, rtol=0, atol=1e-5)
    assert dop["value"].iloc[0] == pytest.approx(-809.2735, abs=1e-5)
    # INTEGRATION_REF = START, INTEGRATION_INTERVAL = 1 s: re-tagged to mid-interval
    assert list(dop["time"]) == [utc("2005-06-08T17:41:00.5"), utc("2005-06-08T17:41:01.5"),
                                 utc("2005-06-08T17:41:02.5")]
    assert list(dop["row"]) == [23, 24, 26]

    rr = f[f["kind"] == "range_rate"]
    np.testing.assert_allclose(rr["value"], [1234.0, -500.0])   # km/s -> m/s, sign kept
    assert list(rr["time"]) == [utc("2005-06-08T17:42:00"), utc("2005-06-08T17:42:10.5")]
    assert list(rr["row"]) == [37, 38]

    assert raw.meta["doppler_mode"] == "one-way"
    assert raw.meta["carrier_hz"] == pytest.approx(tx)
    assert raw.meta["tdm_segments"] == 2
    assert raw.meta["source"].endswith("oneway_doppler.tdm")
    assert raw.meta["skipped_keywords"] == {"PR_N0": 2}
    assert raw.column == {"doppler": "RECEIVE_FREQ_1", "range_rate": "DOPPLER_INSTANTANEOUS"}


def test_two_way_range_is_halved_and_recorded():
    raw = load("twoway_range.tdm", two_way_range="round-trip")
    f = raw.frame
    rng = f[f["kind"] == "range"]
    # (2467.5 km + CORRECTION_RANGE 0.5 km, CORRECTIONS_APPLIED = NO) / 2 -> 1234 km
    assert rng["value"].iloc[0] == pytest.approx(1234.0e3, abs=1e-6)
    assert rng["value"].iloc[1] == pytest.approx(1235.0e3, abs=1e-6)
    # RANGE_UNITS = s: light time x c / 2; the correction is already applied (YES)
    assert rng["value"].iloc[2] == pytest.approx(0.016 * C_LIGHT / 2, abs=1e-6)
    assert list(rng["station"]) == ["HBSTK", "HBSTK", "WHM1"]
    assert list(rng["row"]) == [20, 23, 37]
    assert raw.meta["range_two_way_halved"] is True

    rr = f[f["kind"] == "range_rate"]
    np.testing.assert_allclose(rr["value"], [-1234.0, 250.0])  # not halved: a rate
    # INTEGRATION_REF = END, 10 s: the mean rate belongs 5 s before the tag
    assert list(rr["time"]) == [utc("2020-01-15T10:00:05"), utc("2020-01-15T10:01:05")]
    assert raw.meta["doppler_mode"] == "two-way"
    assert raw.meta["skipped_keywords"] == {"PR_N0": 2}
    assert any("TRANSMIT_DELAY_1" in w for w in raw.meta["warnings"])
    assert "carrier_hz" not in raw.meta


def test_two_way_range_written_as_one_way_equivalent_by_default():
    raw = load("twoway_range.tdm")
    rng = raw.frame[raw.frame["kind"] == "range"]
    assert rng["value"].iloc[0] == pytest.approx(2468.0e3, abs=1e-6)
    assert raw.meta["range_two_way_halved"] is False


def test_one_way_range_is_not_halved():
    raw = read_tdm(tdm(*HEADER, *meta("RANGE_UNITS = km"), "DATA_START",
                       "RANGE = 2020-01-01T00:00:00 1.234", "DATA_STOP"), "x.tdm")
    assert raw.frame["value"].iloc[0] == pytest.approx(1234.0, abs=1e-9)
    assert raw.meta["range_two_way_halved"] is False


def test_two_way_receive_freq_with_turnaround_and_ramp():
    raw = load("twoway_receive_freq.tdm")
    f = raw.frame
    ratio = 240 / 221
    nominal = [2210000000.0 * ratio,                       # at the TRANSMIT_FREQ tag
               (2210000000.0 + 10.0 * 100) * ratio,        # 100 s into a 10 Hz/s ramp
               (2210005000.0 + 10.0 * 50) * ratio]         # new TRANSMIT_FREQ, ramp goes on
    received = [2400000500.0, 2399999085.97285, 2400005000.0]
    np.testing.assert_allclose(f["value"], np.subtract(received, nominal), rtol=0, atol=1e-5)
    assert f["value"].iloc[0] == pytest.approx(500.0, abs=1e-5)
    assert f["value"].iloc[1] == pytest.approx(-2000.0, abs=1e-4)
    assert set(f["kind"]) == {"doppler"}
    assert raw.meta["doppler_mode"] == "two-way"
    assert raw.meta["carrier_hz"] == pytest.approx(nominal[1])


def test_azel_angles_with_tabs_and_day_of_year_epochs():
    raw = load("azel_tabs_doy.tdm")
    f = raw.frame
    az = f[f["kind"] == "azimuth"]
    el = f[f["kind"] == "elevation"]
    np.testing.assert_allclose(az["value"], [math.radians(10.0), math.radians(270.0),
                                             math.radians(359.5)], rtol=0, atol=1e-12)
    # 10 deg; 45 deg; 30.5 deg + CORRECTION_ANGLE_2 (-0.5, not yet applied)
    np.testing.assert_allclose(el["value"], [math.radians(10.0), math.radians(45.0),
                                             math.radians(30.0)], rtol=0, atol=1e-12)
    assert el["value"].iloc[0] == pytest.approx(0.17453292519943295, abs=1e-15)
    # day 031 = 31 January, day 032 = 1 February; with and without 'Z'
    assert list(az["time"]) == [utc("2021-01-31T23:59:59.25"), utc("2021-02-01T00:00:00"),
                                utc("2021-02-01T00:00:01.5")]
    assert list(az["station"]) == ["RADAR-A", "RADAR-A", "TELESCOPE-B"]  # no PATH: PARTICIPANT_1
    assert list(f["row"]) == [14, 15, 18, 19, 32, 33]
    assert "doppler_mode" not in raw.meta
    assert raw.column == {"azimuth": "ANGLE_1", "elevation": "ANGLE_2"}


def test_tai_gps_tt_converted_to_utc_with_leap_seconds():
    raw = load("time_systems_2020.tdm")
    t = list(raw.frame["time"])
    noon = utc("2020-06-01T12:00:00")
    assert t[0] == noon                                    # TAI - 37 s in 2020
    assert t[0] - pd.Timestamp("2020-06-01T12:00:37", tz="UTC") == pd.Timedelta(seconds=-37)
    assert t[1] == utc("2020-06-01T12:00:01.5")            # day-of-year 153 = 1 June 2020
    assert t[2] == noon                                    # GPS - 18 s (= TAI - 19 s - 37 s)
    assert t[3] == noon                                    # TT - 32.184 s - 37 s
    assert t[4] == utc("2016-12-31T23:59:34")              # before the 2016 leap: 36 s
    assert t[5] == utc("2017-01-01T00:00:03")              # after it: 37 s
    assert raw.meta["source_time_systems"] == ["GPS", "TAI", "TT"]
    assert raw.meta["tdm_segments"] == 4


def test_carrier_argument_when_no_transmit_freq():
    data = tdm(*HEADER, *meta(), "DATA_START",
               "RECEIVE_FREQ_1 = 2020-01-01T00:00:00 437500123.5", "DATA_STOP")
    raw = read_tdm(data, "x.tdm", carrier_hz=437.5e6)
    assert raw.frame["value"].iloc[0] == pytest.approx(123.5, abs=1e-6)
    assert raw.meta["carrier_hz"] == 437.5e6
    assert raw.meta["doppler_mode"] == "one-way"


def test_unknown_data_keywords_are_counted_not_silent():
    data = tdm(*HEADER, *meta(), "DATA_START",
               "CARRIER_POWER = 2020-01-01T00:00:00 -150.0",
               "STEC = 2020-01-01T00:00:00 12.0",
               "STEC = 2020-01-01T00:00:01 12.5",
               "MY_OWN_THING = 2020-01-01T00:00:01 1",
               "DOPPLER_INSTANTANEOUS = 2020-01-01T00:00:00 0.001",
               "DATA_STOP")
    raw = read_tdm(data, "x.tdm")
    assert raw.meta["skipped_keywords"] == {"CARRIER_POWER": 1, "MY_OWN_THING": 1, "STEC": 2}
    assert raw.frame["value"].iloc[0] == pytest.approx(1.0)


def test_transmit_freq_not_used_for_doppler_is_counted():
    # as in the spec's DSN range example: up-link frequency and ramp given with RANGE only
    data = tdm(*HEADER, *meta(path="1,2,1"), "DATA_START",
               "TRANSMIT_FREQ_1 = 2020-01-01T00:00:00 7180064367.3536",
               "TRANSMIT_FREQ_RATE_1 = 2020-01-01T00:00:00 0.59299",
               "RANGE = 2020-01-01T00:00:00 2.0", "DATA_STOP")
    raw = read_tdm(data, "x.tdm")
    assert raw.meta["skipped_keywords"] == {"TRANSMIT_FREQ_1": 1, "TRANSMIT_FREQ_RATE_1": 1}
    assert raw.frame["value"].iloc[0] == pytest.approx(2000.0)  # one-way equivalent, as written
    assert any("one-way equivalents" in w for w in raw.meta["warnings"])
    halved = read_tdm(data, "x.tdm", two_way_range="round-trip")
    assert halved.frame["value"].iloc[0] == pytest.approx(1000.0)


def test_crlf_bom_lowercase_and_spacing_are_accepted():
    text = ("\ufeffCCSDS_TDM_VERS=1.0\r\nORIGINATOR = X\r\nmeta_start\r\ntime_system=utc\r\n"
            "PARTICIPANT_1=STA\r\nPARTICIPANT_2=SAT\r\npath = 2, 1\r\nMETA_STOP\r\n"
            "DATA_START\r\ndoppler_instantaneous=2020-001T00:00:00.000Z    -2.5\r\nDATA_STOP\r\n")
    raw = read_tdm(text.encode("utf-8"), "x.tdm")
    assert raw.frame["value"].iloc[0] == -2500.0
    assert raw.frame["time"].iloc[0] == utc("2020-01-01T00:00:00")
    assert raw.frame["row"].iloc[0] == 10


# ------------------------------------------------------------------------------------ errors


@pytest.mark.parametrize("data", [b"", b"  \n\t\n", b"COMMENT nothing else\n\nCOMMENT\n"])
def test_empty_file(data):
    err = read_error(data)
    assert "empty" in str(err)
    assert err.row is None


def test_missing_version_names_first_line():
    err = read_error(tdm("CREATION_DATE = 2020-01-01T00:00:00", "ORIGINATOR = X", *meta(),
                         "DATA_START", "RANGE = 2020-01-01T00:00:00 1.0", "DATA_STOP"))
    assert (err.row, err.column) == (1, "CCSDS_TDM_VERS")
    err = read_error(tdm("COMMENT first a comment", "", "META_START"))
    assert (err.row, err.column) == (3, "CCSDS_TDM_VERS")
    assert "missing CCSDS_TDM_VERS" in str(err)


def test_data_before_first_meta_block():
    err = read_error(tdm(*HEADER, "RANGE = 2020-01-01T00:00:00 1.0", *meta(), "DATA_START",
                         "DATA_STOP"))
    assert (err.row, err.column) == (4, "RANGE")
    assert "outside DATA_START/DATA_STOP" in str(err)


def test_data_after_data_stop():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "RANGE = 2020-01-01T00:00:00 1.0",
                         "DATA_STOP", "RANGE = 2020-01-01T00:00:01 1.0"))
    assert (err.row, err.column) == (13, "RANGE")
    assert "outside DATA_START/DATA_STOP" in str(err)


def test_data_between_meta_stop_and_data_start():
    err = read_error(tdm(*HEADER, *meta(), "ANGLE_1 = 2020-01-01T00:00:00 1.0", "DATA_START",
                         "DATA_STOP"))
    assert (err.row, err.column) == (10, "ANGLE_1")
    assert "outside DATA_START/DATA_STOP" in str(err)


@pytest.mark.parametrize("epoch", ["2020-13-01T00:00:00", "2021-366T00:00:00",
                                   "2020-01-01 00:00:00", "2020-01-01T25:00:00", "yesterday",
                                   "2020-02-30T00:00:00"])
def test_unparseable_epoch(epoch):
    data = ("\n".join([*HEADER, *meta(), "DATA_START",
                       "RANGE = 2020-01-01T00:00:00 1.0",
                       f"RANGE = {epoch} 1.0", "DATA_STOP"]) + "\n").encode()
    err = read_error(data)
    assert err.row == 12
    assert err.column == "RANGE"
    assert "epoch" in str(err) or "epoch and one value" in str(err)


def test_unparseable_epoch_message_names_the_formats():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "RANGE = 2020/01/01T00:00:00 1.0",
                         "DATA_STOP"))
    assert err.row == 11 and err.column == "RANGE"
    assert err.found == "2020/01/01T00:00:00"
    assert "YYYY-DDDThh:mm:ss" in str(err)


@pytest.mark.parametrize("value", ["abc", "1.2.3", "0x10", "1,5", "1_000"])
def test_non_numeric_value(value):
    err = read_error(tdm(*HEADER, *meta(), "DATA_START",
                         f"DOPPLER_INSTANTANEOUS = 2020-01-01T00:00:00 {value}", "DATA_STOP"))
    assert (err.row, err.column, err.found) == (11, "DOPPLER_INSTANTANEOUS", value)
    assert "non-numeric" in str(err)


def test_non_numeric_metadata():
    err = read_error(tdm(*HEADER, *meta("FREQ_OFFSET = lots"), "DATA_START",
                         "RECEIVE_FREQ_1 = 2020-01-01T00:00:00 1.0", "DATA_STOP"))
    assert (err.row, err.column) == (9, "FREQ_OFFSET")


def test_unbalanced_meta_stop_without_start():
    err = read_error(tdm(*HEADER, "META_STOP"))
    assert (err.row, err.column) == (4, "META_STOP")
    assert "unbalanced" in str(err)


def test_unbalanced_data_start_inside_meta():
    err = read_error(tdm(*HEADER, "META_START", "TIME_SYSTEM = UTC", "DATA_START"))
    assert (err.row, err.column) == (6, "DATA_START")
    assert "META_START at row 4 is still open" in str(err)


def test_unbalanced_missing_data_stop_at_end():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "RANGE = 2020-01-01T00:00:00 1.0"))
    assert (err.row, err.column) == (10, "DATA_STOP")
    assert "no DATA_STOP" in str(err)


def test_unbalanced_missing_meta_stop_at_end():
    err = read_error(tdm(*HEADER, "META_START", "TIME_SYSTEM = UTC"))
    assert (err.row, err.column) == (4, "META_STOP")


def test_unbalanced_meta_without_data_block():
    err = read_error(tdm(*HEADER, *meta()))
    assert (err.row, err.column) == (9, "DATA_START")


def test_unbalanced_data_block_without_meta():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "DATA_STOP", "DATA_START"))
    assert (err.row, err.column) == (12, "DATA_START")
    assert "unbalanced" in str(err)


def test_unbalanced_meta_start_inside_data():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "META_START"))
    assert (err.row, err.column) == (11, "META_START")
    assert "DATA_START at row 10 is still open" in str(err)


def test_metadata_after_data_stop_without_meta_start():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "DATA_STOP", "TIME_SYSTEM = UTC"))
    assert (err.row, err.column) == (12, "TIME_SYSTEM")


def test_header_only_file():
    err = read_error(tdm(*HEADER))
    assert err.column == "META_START"


def test_garbage_line():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "this is not KVN", "DATA_STOP"))
    assert err.row == 11


def test_xml_tdm_is_refused():
    err = read_error(b'<?xml version="1.0"?>\n<tdm id="CCSDS_TDM_VERS" version="2.0"/>\n')
    assert err.row == 1 and "XML" in str(err)


def test_receive_freq_without_carrier_asks_for_carrier_hz():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START",
                         "RECEIVE_FREQ_1 = 2020-01-01T00:00:00 437500123.5", "DATA_STOP"))
    assert (err.row, err.column) == (11, "RECEIVE_FREQ_1")
    assert "--carrier-hz" in str(err)


def test_receive_freq_far_from_carrier():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START",
                         "RECEIVE_FREQ_1 = 2020-01-01T00:00:00 -4000.0", "DATA_STOP"),
                     carrier_hz=437.5e6)
    assert (err.row, err.column) == (11, "RECEIVE_FREQ_1")
    assert "FREQ_OFFSET" in str(err)


def test_two_way_receive_freq_without_turnaround_is_caught():
    err = read_error(tdm(*HEADER, *meta(path="1,2,1"), "DATA_START",
                         "TRANSMIT_FREQ_1 = 2020-01-01T00:00:00 2210000000.0",
                         "RECEIVE_FREQ_1 = 2020-01-01T00:00:00 2400000500.0", "DATA_STOP"))
    assert (err.row, err.column) == (12, "RECEIVE_FREQ_1")
    assert "turnaround" in str(err)


@pytest.mark.parametrize("angle_type", ["RADEC", "XEYN", "XSYE"])
def test_other_angle_types_are_refused_by_name(angle_type):
    err = read_error(tdm(*HEADER, *meta(f"ANGLE_TYPE = {angle_type}"), "DATA_START",
                         "ANGLE_1 = 2020-01-01T00:00:00 10.0", "DATA_STOP"))
    assert (err.row, err.column) == (12, "ANGLE_1")
    assert angle_type in str(err)


def test_angles_without_angle_type():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "ANGLE_2 = 2020-01-01T00:00:00 10.0",
                         "DATA_STOP"))
    assert (err.row, err.column) == (11, "ANGLE_2")
    assert "ANGLE_TYPE" in str(err)


def test_range_units_ru_are_refused_with_reason():
    err = read_error(tdm(*HEADER, *meta("RANGE_UNITS = RU", path="1,2,1"), "DATA_START",
                         "RANGE = 2020-01-01T00:00:00 39242998.5", "DATA_STOP"))
    assert (err.row, err.column) == (12, "RANGE")
    assert "RU" in str(err) and "RANGE_MODULUS" in str(err)


@pytest.mark.parametrize("system", ["TDB", "UT1", "MET", "SCLK"])
def test_unsupported_time_system(system):
    err = read_error(tdm(*HEADER, *meta(time_system=system), "DATA_START",
                         "RANGE = 2020-01-01T00:00:00 1.0", "DATA_STOP"))
    assert (err.row, err.column, err.found) == (5, "TIME_SYSTEM", system)


def test_missing_time_system():
    err = read_error(tdm(*HEADER, "META_START", "PARTICIPANT_1 = STA", "META_STOP",
                         "DATA_START", "ANGLE_2 = 2020-01-01T00:00:00 1.0", "DATA_STOP"))
    assert (err.row, err.column) == (4, "TIME_SYSTEM")


def test_transmit_time_tags_are_refused():
    err = read_error(tdm(*HEADER, *meta("TIMETAG_REF = TRANSMIT"), "DATA_START",
                         "RANGE = 2020-01-01T00:00:00 1.0", "DATA_STOP"))
    assert (err.row, err.column) == (9, "TIMETAG_REF")


def test_relay_path_is_refused():
    lines = (*HEADER, "META_START", "TIME_SYSTEM = UTC", "PARTICIPANT_1 = STA",
             "PARTICIPANT_2 = RELAY", "PARTICIPANT_3 = SAT", "PATH = 1,2,3,2,1", "META_STOP",
             "DATA_START", "RANGE = 2020-01-01T00:00:00 80452.7", "DATA_STOP")
    err = read_error(tdm(*lines))
    assert (err.row, err.column) == (12, "RANGE")
    assert "1,2,3,2,1" in str(err)


def test_path_with_undefined_participant():
    err = read_error(tdm(*HEADER, *meta(path="3,1"), "DATA_START", "DATA_STOP"))
    assert (err.row, err.column) == (8, "PATH")


def test_doppler_without_path():
    err = read_error(tdm(*HEADER, *meta(path=""), "DATA_START",
                         "DOPPLER_INSTANTANEOUS = 2020-01-01T00:00:00 1.0", "DATA_STOP"))
    assert (err.row, err.column) == (10, "DOPPLER_INSTANTANEOUS")
    assert "PATH" in str(err)


def test_mixed_doppler_modes_in_one_file():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START",
                         "DOPPLER_INSTANTANEOUS = 2020-01-01T00:00:00 1.0", "DATA_STOP",
                         *meta(path="1,2,1"), "DATA_START",
                         "DOPPLER_INSTANTANEOUS = 2020-01-01T00:00:01 1.0", "DATA_STOP"))
    assert (err.row, err.column) == (20, "DOPPLER_INSTANTANEOUS")
    assert "one Doppler mode" in str(err)


def test_correction_without_corrections_applied_is_ambiguous():
    err = read_error(tdm(*HEADER, *meta("CORRECTION_RANGE = 0.01"), "DATA_START",
                         "RANGE = 2020-01-01T00:00:00 1.0", "DATA_STOP"))
    assert (err.row, err.column) == (9, "CORRECTIONS_APPLIED")


def test_data_line_with_extra_fields():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START",
                         "RANGE = 2020-01-01T00:00:00 1.0 2.0", "DATA_STOP"))
    assert (err.row, err.column) == (11, "RANGE")


def test_only_unsupported_data_is_an_error_naming_what_was_skipped():
    err = read_error(tdm(*HEADER, *meta(), "DATA_START", "PR_N0 = 2020-01-01T00:00:00 28.0",
                         "DATA_STOP"))
    assert "PR_N0 x1" in str(err)


def test_bad_carrier_argument():
    with pytest.raises(InputError):
        read_tdm(tdm(*HEADER), "x.tdm", carrier_hz=-1.0)


def test_binary_input_is_refused():
    err = read_error(b"PAR1\x00\x01\x02")
    assert err.row == 1


def test_range_only_file_takes_its_paths_link_mode():
    """Two-way RANGE alone makes the file two-way (estimate models its ranges as round trips);
    ranges whose path differs from the Doppler's are named in a warning."""
    two = read_tdm(tdm(*HEADER, *meta("RANGE_UNITS = km", path="1,2,1"), "DATA_START",
                       "RANGE = 2020-01-01T00:00:00 1.234", "DATA_STOP"), "x.tdm")
    assert two.meta["doppler_mode"] == "two-way" and two.meta["range_source_paths"] == ["two-way"]
    mixed = read_tdm(tdm(*HEADER, *meta("RANGE_UNITS = km", path="1,2,1"), "DATA_START",
                         "RANGE = 2020-01-01T00:00:00 1.234", "DATA_STOP",
                         *meta(), "DATA_START", "DOPPLER_INSTANTANEOUS = 2020-01-01T00:00:01 0.5", "DATA_STOP"),
                     "x.tdm")
    assert mixed.meta["doppler_mode"] == "one-way"
    assert any("RANGE paths are two-way" in w and "split the file by path" in w for w in mixed.meta["warnings"])
