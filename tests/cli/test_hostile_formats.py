"""Hostile class, round 3: the formats and commands added since (TLE catalogues, ICGEM gravity
fields, CRD, CPF, SINEX, defaults files, fit-tle, identify, passes, full-force propagate, batch).
Each refusal is checked for its exit code, one line on stderr naming the file/row/field, no
traceback and no output left behind; the TLE grammar is also fuzzed (hypothesis, bounded)."""

from __future__ import annotations

import gzip
import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hostile import DOPPLER_CSV, MULTI, STATIONS, TRUTH_DOC, assert_no_temporaries, assert_rejected, state_doc
from trackproc.io.tle import checksum

L1 = "1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927"
L2 = "2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537"


def _sum(line: str) -> str:
    return line[:68] + str(checksum(line))


def _put(line: str, col: int, text: str) -> str:
    """``text`` at 1-based column ``col`` of ``line``, checksum recomputed."""
    return _sum(line[:col - 1] + text + line[col - 1 + len(text):])


# -- TLE: each field SGP4 uses, named at its row and columns --------------------------------------

@pytest.mark.parametrize("line1, line2, row, needles", [
    (_put(L1, 19, "08367.51782528"), L2, 1, ["epoch day", "leap year"]),
    (_put(L1, 19, "09366.00000000"), L2, 1, ["epoch day", "not a leap year"]),
    (_put(L1, 19, "08000.50000000"), L2, 1, ["epoch day"]),
    (L1, _put(L2, 53, "-15.7212539"), 2, ["mean motion", "revolutions per day"]),
    (L1, _put(L2, 53, " 0.00000000"), 2, ["mean motion"]),
    (L1, _put(L2, 53, "25.00000000"), 2, ["mean motion"]),
    (L1, _put(L2, 9, "     nan"), 2, ["inclination"]),
    (L1, _put(L2, 9, "200.0000"), 2, ["inclination", "0 to 180"]),
    (L1, _put(L2, 44, "400.0000"), 2, ["mean anomaly"]),
    (L1, _put(L2, 27, "00x6703"), 2, ["eccentricity"]),
    (_put(L1, 54, " 11606+3"), L2, 1, ["B*", "|B*| < 1"]),
    (_put(L1, 54, " 1x606-4"), L2, 1, ["B*"]),
])
def test_tle_fields(run_cli, write, tmp_path, line1, line2, row, needles):
    tle = write("bad.tle", f"ISS\n{line1}\n{line2}\n")
    out = tmp_path / "o.csv"
    result = run_cli(["propagate", tle, "--span", "600", "--step", "60", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "bad.tle", f"row {row + 1}", *needles, outputs=[out], folder=tmp_path)


def test_catalogue_rows_duplicates_and_bound(run_cli, write, tmp_path):
    good = f"ISS\n{L1}\n{L2}\n"
    # line 2 short: named at line 2's row (row 6), not at line 1's
    cat = write("cat.tle", good + f"OTHER\n{L1}\n{L2[:60]}\n")
    out = tmp_path / "r.json"
    passes = tmp_path / "p.parquet"
    sim = run_cli(["simulate", "--tle", write("iss.tle", good), "--stations", STATIONS, "--duration", "21600",
                   "--step", "30", "--kinds", "doppler", "--carrier-hz", "145.8e6", "--dut1", "0", "-q", "-o", passes])
    assert sim.exit_code == 0, sim.stderr
    result = run_cli(["identify", passes, "--tles", cat, "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "cat.tle", "row 6", outputs=[out])
    # a field error inside the catalogue: its own row and column
    cat = write("cat2.tle", good + f"OTHER\n{_put(L1, 19, '08367.0')}\n{L2}\n")
    result = run_cli(["identify", passes, "--tles", cat, "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "cat2.tle", "row 5", "epoch day", outputs=[out])
    # the same catalogue number twice: a warning, still ranked
    cat = write("cat3.tle", good + good)
    result = run_cli(["identify", passes, "--tles", cat, "--dut1", "0", "-o", out])
    assert result.exit_code == 0, result.stderr
    assert "25544 at rows 1 and 4" in result.stderr and "WARNING" in result.stderr
    # a bound on the catalogue's size, naming the option that raises it
    result = run_cli(["identify", passes, "--tles", cat, "--max-candidates", "1", "--dut1", "0", "-q", "-o", out])
    out.unlink()
    assert_rejected(result, 2, "--max-candidates", outputs=[out])


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(line=st.sampled_from([1, 2]), col=st.integers(min_value=3, max_value=68),
       text=st.text(alphabet="0123456789 .-+eEnaif", min_size=1, max_size=11))
def test_tle_grammar_fuzz(run_cli, tmp_path, line, col, text):
    """Any edit of the element columns (checksum kept valid): a state (exit 0) whose numbers are
    finite, or one line naming the file and a row (exit 2); never a traceback or exit 1."""
    l1, l2 = (_put(L1, col, text[:69 - col]), L2) if line == 1 else (L1, _put(L2, col, text[:69 - col]))
    tle = tmp_path / "f.tle"
    tle.write_text(f"{l1}\n{l2}\n")
    out = tmp_path / "o.csv"
    if out.exists():
        out.unlink()
    result = run_cli(["propagate", tle, "--span", "60", "--step", "60", "--dut1", "0", "-q", "-o", out])
    assert "Traceback" not in result.stderr
    if result.exit_code == 0:
        assert out.exists()
    else:
        assert_rejected(result, 2, "f.tle", "row ", outputs=[out], folder=tmp_path)


# -- ICGEM: the header against the content ----------------------------------------------------

HEAD = ("begin_of_head\nmodelname TEST\nearth_gravity_constant 3.986004415E+14\nradius 6378136.3\n"
        "max_degree {deg}\nnorm fully_normalized\nerrors formal\nend_of_head\n")
BODY = "gfc 0 0 1.0 0 0 0\ngfc 2 0 -4.84e-4 0 0 0\ngfc 2 1 0 0 0 0\ngfc 2 2 2.4e-6 -1.4e-6 0 0\n"
FIELDS = {
    "radius_inf": (HEAD.format(deg=2).replace("6378136.3", "inf") + BODY, ["radius"]),
    "radius_km": (HEAD.format(deg=2).replace("6378136.3", "6378.1363") + BODY, ["radius", "metres"]),
    "gm_km": (HEAD.format(deg=2).replace("3.986004415E+14", "398600.4415") + BODY, ["earth_gravity_constant"]),
    "header_2000": (HEAD.format(deg=2000) + BODY, ["L=3 M=0 missing", "header max_degree 2000"]),
    "header_1e8": (HEAD.format(deg=100000000) + BODY, ["max_degree", "10800"]),
    "twice": (HEAD.format(deg=2) + BODY + "gfc 2 0 -4.85e-4 0 0 0\n", ["row 13", "listed twice"]),
    "nan": (HEAD.format(deg=2) + BODY.replace("-4.84e-4", "nan"), ["L=2 M=0"]),
    "no_end": (HEAD.format(deg=2).replace("end_of_head\n", "") + BODY, ["end_of_head"]),
    "cut_gz": (gzip.compress((HEAD.format(deg=2) + BODY * 50).encode())[:120], ["cut short"]),
}


@pytest.mark.parametrize("case", list(FIELDS))
def test_icgem_header_against_content(run_cli, write, tmp_path, case):
    text, needles = FIELDS[case]
    gravity = 3 if case == "header_2000" else 2
    field = write("bad.gfc.gz" if case == "cut_gz" else "bad.gfc", text)
    out = tmp_path / "o.csv"
    result = run_cli(["propagate", TRUTH_FILE(write), "--force", "full", "--gravity", str(gravity), "--gravity-field",
                      field, "--third-body", "none", "--no-relativity", "--span", "60", "--step", "60", "--dut1", "0",
                      "-q", "-o", out])
    assert_rejected(result, 2, field.name, *needles, outputs=[out], folder=tmp_path)


def TRUTH_FILE(write):
    return write("s.json", state_doc())


def test_gravity_degree_bound(run_cli, write, tmp_path):
    out = tmp_path / "o.csv"
    result = run_cli(["propagate", TRUTH_FILE(write), "--force", "full", "--gravity", "500", "--span", "60",
                      "--step", "60", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "--gravity", "360", outputs=[out])


# -- CRD: record types and end records --------------------------------------------------------

CRD = """h1 CRD  1 2016  2 13 23
h2 YARL       7090  5 13 3
h3 lageos2     9207002 5986    22195 0 1
h4  1 2016  2 13 23 50  0 2016  2 14  0 10  0  0 0 0 0 1 0 2 0
11 85900.000000000000     0.039237325685 std 2  120.0     94   57.0   0.183  -0.536      -1.0  15.67 0
h8
h9
"""


@pytest.mark.parametrize("text, row, needles", [
    (CRD.replace("h8\nh9\n", ""), 5, ["end records", "H8"]),
    (CRD.replace("h9\n", ""), 6, ["no H9"]),
    (CRD.replace("h8\n", ""), 6, ["H9", "inside a session"]),
    (CRD.replace("h8\n", "77 1 2 3\nh8\n"), 6, ["unknown CRD record type"]),
    (CRD + "11 1 0.04 std 2 1 1 1 0 0 -1 1 0\n", 8, ["after the end of file"]),
])
def test_crd_structure(run_cli, write, tmp_path, text, row, needles):
    from test_sinex import SNX

    npt = write("bad.npt", text)
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", npt, "--stations", write("s.snx", SNX), "-q", "-o", out])
    assert_rejected(result, 2, "bad.npt", f"row {row}", *needles, outputs=[out], folder=tmp_path)


# -- SINEX: plausible velocities and positions ------------------------------------------------

@pytest.mark.parametrize("edit, needles", [
    (("-.468389138240797E-01", "0.1E+07"), ["VELX/VELY/VELZ", "1 m/yr"]),
    (("-.238900753398029E+07 0.51901E-03\n   212", "-.238900753398029E+04 0.51901E-03\n   212"), ["STAX"]),
])
def test_sinex_plausibility(run_cli, write, tmp_path, edit, needles):
    from test_crd import V1
    from test_sinex import SNX

    assert edit[0] in SNX
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", write("v1.npt", V1), "--stations", write("bad.snx", SNX.replace(*edit)), "-q",
                      "-o", out])
    assert_rejected(result, 2, "bad.snx", *needles, outputs=[out], folder=tmp_path)


# -- SINEX: block structure (a cut transfer, an edited file) ----------------------------------

@pytest.mark.parametrize("edit, needles", [
    (lambda t: t[:t.index("-SOLUTION/ESTIMATE")], ["SOLUTION/ESTIMATE not closed", "cut short"]),
    (lambda t: t.replace("-SOLUTION/ESTIMATE", "-SOLUTION/EPOCHS", 1), ["closed as SOLUTION/EPOCHS"]),
    (lambda t: t.replace("-SOLUTION/ESTIMATE\n", "", 1), ["not closed before the next one opens"]),
])
def test_sinex_block_structure(run_cli, write, tmp_path, edit, needles):
    from test_crd import V1
    from test_sinex import SNX

    bad = edit(SNX)
    assert bad != SNX
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", write("v1.npt", V1), "--stations", write("bad.snx", bad), "-q", "-o", out])
    assert_rejected(result, 2, "bad.snx", *needles, outputs=[out], folder=tmp_path)


# -- CPF: units, records, span (propagate --compare) ------------------------------------------

def _cpf(days_from_state: float = 0.0, records: int = 3, scale: float = 1.0) -> str:
    mjd = 61119 + int(days_from_state)              # 2026-03-20, the state's day
    lines = ["H1 CPF  1  SGF 2026  3 20  2  5441 test",
             "H2  9207002 5986    22195 2026  3 20  0  0  0 2026  3 20 23 54  0   300 1 1  0 0 0"]
    for k in range(records):
        lines.append(f"10 0 {mjd} {34200 + 60 * k}.0 0 {3774841.0 * scale:.3f} {-1538034.0 * scale:.3f} "
                     f"{5924146.0 * scale:.3f}")
    return "\n".join(lines + ["99"]) + "\n"


@pytest.mark.parametrize("text, needles", [
    (_cpf(scale=1e-3), ["row 3", "kilometres"]),
    (_cpf(records=1), ["--compare", "single CPF position"]),
    (_cpf(days_from_state=3650), ["--compare", "400 days"]),
])
def test_cpf_reference(run_cli, write, tmp_path, text, needles):
    out = tmp_path / "o.csv"
    result = run_cli(["propagate", TRUTH_FILE(write), "--force", "j2", "--span", "600", "--step", "60", "--compare",
                      write("bad.sgf", text), "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "bad.sgf", *needles, outputs=[out], folder=tmp_path)


# -- options and spacecraft -------------------------------------------------------------------

def test_passes_carrier_range(run_cli, write, tmp_path):
    out = tmp_path / "p.csv"
    result = run_cli(["passes", write("iss.tle", f"{L1}\n{L2}\n"), "--stations", STATIONS, "--carrier-hz", "1e20",
                      "--span", "86400", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "--carrier-hz", "1e+12", outputs=[out])


@pytest.mark.parametrize("spacecraft, needle", [
    ({"mass_kg": 1.0, "srp_area_m2": 1.0, "cr": 1e9}, "spacecraft.cr"),
    ({"mass_kg": 1e-9, "drag_area_m2": 1.0}, "spacecraft.mass_kg"),
    ({"mass_kg": 1.0, "drag_area_m2": 500.0}, "area-to-mass"),
])
def test_spacecraft_in_state_file(run_cli, write, tmp_path, spacecraft, needle):
    state = write("sc.json", state_doc(spacecraft=spacecraft))
    out = tmp_path / "o.csv"
    result = run_cli(["propagate", state, "--force", "full", "--gravity", "2", "--third-body", "none", "--span", "60",
                      "--step", "60", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, needle, outputs=[out])


def test_sigma_floor_at_ingest(run_cli, write, tmp_path):
    raw = write("r.csv", "time,station,range_m,sigma_range_m\n2026-03-20T09:30:00Z,CPH,1000000,1e-300\n")
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", raw, "--stations", STATIONS, "-q", "-o", out])
    assert_rejected(result, 2, "r.csv", "row 2", "sigma_range_m", "1e-06", outputs=[out])


@pytest.mark.parametrize("toml, needles", [
    ('[defaults]\ncarrier_hz = "abc"\n', ["[defaults] carrier_hz", "number"]),
    ('[propagate]\nforce = "fulll"\n', ["[propagate] force", "j2"]),
    ("[defaults]\ndut1 = [1, 2]\n", ["[defaults] dut1"]),
])
def test_defaults_file_types(run_cli, write, tmp_path, monkeypatch, toml, needles):
    monkeypatch.setenv("TRACKPROC_CONFIG", str(write("conf.toml", toml)))
    out = tmp_path / "o.csv"
    result = run_cli(["propagate", TRUTH_FILE(write), "--span", "60", "--step", "60", "-q", "-o", out])
    assert_rejected(result, 2, "conf.toml", *needles, outputs=[out])


def test_estimate_sample_bound(run_cli, tmp_path):
    from hostile import TRUTH

    out = tmp_path / "e.json"
    result = run_cli(["estimate", MULTI, "--initial", TRUTH, "--max-samples", "100", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "--max-samples", outputs=[out])


def test_reentry_stops_with_its_time(run_cli, write, tmp_path):
    """A circular orbit at 150 km with A/m 0.05 m^2/kg decays within an hour (Harris-Priester):
    the propagation stops at ~100 km and says when; the radius check against the closed form
    of a circular speed keeps the state physical."""
    r = 6378137.0 + 150e3
    v = math.sqrt(3.986004418e14 / r)
    state = write("low.json", json.dumps({"epoch": "2026-03-20T09:30:00Z", "frame": "GCRF", "position_m": [r, 0, 0],
                                          "velocity_m_s": [0, v * math.cos(0.9), v * math.sin(0.9)],
                                          "spacecraft": {"mass_kg": 1.0, "drag_area_m2": 0.05, "cd": 2.2}}))
    out = tmp_path / "o.parquet"
    result = run_cli(["propagate", state, "--force", "full", "--gravity", "4", "--third-body", "none", "--span",
                      "86400", "--step", "60", "--dut1", "0", "-q", "-o", out])
    line = assert_rejected(result, 1, "re-enters", "6471 km", "2026-03-20T", outputs=[out], folder=tmp_path)
    t = float(line.split("(t = ")[1].split(" s")[0])
    assert 60.0 < t < 86400.0, line


# -- batch ------------------------------------------------------------------------------------

def test_batch_isolates_a_name_that_is_not_utf8(run_cli, tmp_path):
    import os

    inbox = tmp_path / "in"
    inbox.mkdir()
    (inbox / "good.parquet").write_bytes(MULTI.read_bytes())
    os.symlink(MULTI, os.path.join(os.fsencode(inbox), b"bad\xff.parquet"))
    out = tmp_path / "out"
    result = run_cli(["batch", "--input", inbox, "--stations", STATIONS, "--steps", "ingest", "-o", out, "-q"])
    assert result.exit_code == 3, result.stderr
    assert "Traceback" not in result.stderr and "internal error" not in result.stderr
    summary = json.loads((out / "summary.json").read_text())
    text = json.dumps(summary)
    assert "bad\\\\xff" in text and "not valid UTF-8" in text
    assert_no_temporaries(out)


def test_batch_input_size_checked_before_reading(run_cli, tmp_path, monkeypatch):
    inbox = tmp_path / "in"
    inbox.mkdir()
    (inbox / "big.csv").write_bytes(DOPPLER_CSV.read_bytes())
    monkeypatch.setenv("TRACKPROC_MAX_INPUT_MB", "0.001")
    out = tmp_path / "out"
    result = run_cli(["batch", "--input", inbox, "--stations", STATIONS, "--steps", "ingest", "-o", out, "-q"])
    assert result.exit_code == 1, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert "TRACKPROC_MAX_INPUT_MB" in json.dumps(summary)


def test_batch_unwritable_output_is_exit_1(run_cli, tmp_path, monkeypatch):
    """A read-only file system (simulated: the write probe fails with EROFS) is an environment
    failure, exit 1, not a usage error."""
    import errno
    import pathlib

    real = pathlib.Path.write_bytes

    def refuse(self, data):
        if self.name.startswith(".write-test-"):
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return real(self, data)

    monkeypatch.setattr(pathlib.Path, "write_bytes", refuse)
    inbox = tmp_path / "in"
    inbox.mkdir()
    (inbox / "a.csv").write_bytes(DOPPLER_CSV.read_bytes())
    result = run_cli(["batch", "--input", inbox, "--stations", STATIONS, "--steps", "ingest", "-o", tmp_path / "out",
                      "-q"])
    assert_rejected(result, 1, "read-only file system")


# -- time: ERFA's raw warnings never reach the user -------------------------------------------

def test_old_epoch_warns_once_in_our_words(run_cli, write, tmp_path):
    doc = {k: v for k, v in TRUTH_DOC.items() if k != "comment"}
    doc["epoch"] = "1957-10-04T19:28:34Z"
    out = tmp_path / "o.csv"
    result = run_cli(["propagate", write("old.json", json.dumps(doc)), "--span", "600", "--step", "60", "--dut1", "0",
                      "-o", out])
    assert result.exit_code == 0, result.stderr
    assert "ERFA function" not in result.stderr
    assert result.stderr.count("dubious year") == 1, result.stderr


# -- epochs against the data's own span -------------------------------------------------------

def test_a_solution_epoch_years_from_the_samples_is_refused(run_cli, tmp_path):
    """``estimate --epoch`` (or an initial state) decades from the passes would only propagate to the
    step limit: one line naming the option and the span, exit 2, no output."""
    from pathlib import Path

    data = Path(__file__).resolve().parents[2] / "sample_data"
    out = tmp_path / "e.json"
    result = run_cli(["estimate", data / "multistation.parquet", "--initial", data / "truth_at_start.json",
                      "--range-bias", "--epoch", "1990-01-01T00:00:00Z", "-o", out])
    assert result.exit_code == 2, result.stderr
    assert "option '--epoch'" in result.stderr and "days from the samples" in result.stderr
    assert result.stderr.count("\n") == 1 and not out.exists()
