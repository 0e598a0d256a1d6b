"""Property (issue 14 item 7): whatever the bytes of a CSV or TDM input, ``ingest`` ends with exit 0
and a valid pass file, or exit 2 with one error line naming the file and no output; nothing else
(no traceback, no exit 1, no partial file)."""

from __future__ import annotations

import math

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from hostile import TDM_DIR, assert_no_temporaries
from trackproc.io.passfile import read_pass_table

STATIONS = "station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\nKIR,67.857,20.964,400\n"
SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

times = st.one_of(
    st.datetimes(min_value=__import__("datetime").datetime(1500, 1, 1)).map(lambda t: t.isoformat() + "Z"),
    st.sampled_from(["2026-03-20T09:30:00Z", "2026-03-20 09:30:00", "2026-02-30T00:00:00Z", "2300-01-01T00:00:00Z",
                     "", "now", "2026-03-20T25:00:00Z", "1677-09-21T00:12:43Z", "2026-079T09:30:00Z"]),
    st.text(max_size=12))
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-10**30, max_value=10**30).map(str),
    st.sampled_from(["", "nan", "-0", "1e309", "0x10", "1,5", "abc", " 12 "]),
    st.text(max_size=8))
names = st.one_of(st.sampled_from(["CPH", "KIR", "ZHY", "", "cph", "CPH "]), st.text(max_size=6))
value_columns = st.lists(st.sampled_from(["range_m", "range_km", "range_rate_m_s", "doppler_hz", "elevation_deg",
                                          "azimuth_deg", "sigma_range_m", "foo", "range_m"]),
                         min_size=1, max_size=4)


def _cell(text: str) -> str:
    return '"' + text.replace('"', '""') + '"' if any(c in text for c in ',"\n\r') else text


@st.composite
def csv_inputs(draw) -> bytes:
    columns = draw(value_columns)
    header = ["time", "station", *columns]
    if draw(st.booleans()):
        header = draw(st.permutations(header))
    rows = []
    for _ in range(draw(st.integers(min_value=0, max_value=6))):
        cells = {"time": draw(times), "station": draw(names)}
        rows.append(",".join(_cell(cells.get(c) if c in cells else draw(numbers)) for c in header))
    text = ",".join(header) + "\n" + "\n".join(rows) + ("\n" if draw(st.booleans()) else "")
    return text.encode("utf-8", errors="surrogatepass") if draw(st.booleans()) else text.encode("utf-8", "replace")


TEMPLATE = (TDM_DIR / "oneway_doppler.tdm").read_text().splitlines()
KEYWORDS = ["RANGE", "RANGEE", "RECEIVE_FREQ_1", "DOPPLER_INSTANTANEOUS", "ANGLE_1", "ANGLE_2", "PR_N0",
            "TRANSMIT_FREQ_2", "TIME_SYSTEM", "PATH", "MODE", "FOO", "META_START", "DATA_STOP", "COMMENT"]


@st.composite
def tdm_inputs(draw) -> bytes:
    lines = list(TEMPLATE)
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        action = draw(st.sampled_from(["replace", "insert", "delete", "epoch", "value"]))
        i = draw(st.integers(min_value=0, max_value=len(lines) - 1)) if lines else 0
        if action == "delete" and lines:
            del lines[i]
        elif action == "insert":
            lines.insert(i, f"{draw(st.sampled_from(KEYWORDS))} = {draw(times)} {draw(numbers)}")
        elif action == "replace" and lines:
            lines[i] = draw(st.text(max_size=40))
        elif action == "epoch" and lines and "=" in lines[i]:
            key, _, rest = lines[i].partition("=")
            parts = rest.split()
            lines[i] = f"{key}= {draw(times)} {' '.join(parts[1:])}"
        elif action == "value" and lines and "=" in lines[i]:
            key, _, rest = lines[i].partition("=")
            parts = rest.split() or [""]
            lines[i] = f"{key}= {parts[0]} {draw(numbers)}"
    return ("\n".join(lines) + "\n").encode("utf-8", "replace")


def _check(run_cli, tmp_path, data: bytes, suffix: str, *extra):
    raw = tmp_path / f"input{suffix}"
    raw.write_bytes(data)
    out = tmp_path / "out.parquet"
    if out.exists():
        out.unlink()
    stations = tmp_path / "st.csv"
    stations.write_text(STATIONS)
    result = run_cli(["ingest", raw, "--stations", stations, "-q", "-o", out, *extra])
    assert "Traceback" not in result.stderr, result.stderr
    event(f"exit {result.exit_code}")
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    if result.exit_code == 0:
        table = read_pass_table(str(out))
        frame = table.frame
        assert len(frame) > 0
        assert all(math.isfinite(v) for v in frame["value"]) and (frame["sigma"] > 0).all()
        assert not lines, result.stderr
    else:
        assert result.exit_code == 2, result.stderr
        assert len(lines) == 1 and lines[0].startswith("trackproc: error: "), result.stderr
        assert str(raw) in lines[0] or "st.csv" in lines[0] or "--carrier-hz" in lines[0] or "--mode" in lines[0], \
            lines[0]
        assert not out.exists()
    assert_no_temporaries(tmp_path)


@SETTINGS
@given(data=csv_inputs())
def test_csv_reader_exit_0_or_one_line_exit_2(run_cli, tmp_path, data):
    _check(run_cli, tmp_path, data, ".csv", "--carrier-hz", "2.2e9", "--mode", "one-way")


@SETTINGS
@given(data=tdm_inputs())
def test_tdm_reader_exit_0_or_one_line_exit_2(run_cli, tmp_path, data):
    _check(run_cli, tmp_path, data, ".tdm")
