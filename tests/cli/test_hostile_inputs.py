"""Hostile class: the wrong kind of file for every command (missing, a directory, empty, binary,
truncated, the wrong format) is exit 2 and one line naming the file, never a traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostile import MULTI, STATIONS, TRUTH, assert_rejected

NOMINAL = Path(__file__).resolve().parents[1] / "data" / "hostile_nominal.json"

BAD = {
    "missing": None,
    "directory": "DIR",
    "empty": b"",
    "blank": b"\n\n   \n",
    "binary": bytes(range(256)) * 4,
    "nul": b"time,station,range_m\n2026-03-20T09:30:00Z,CPH,1\x00\n",
    "truncated_parquet": MULTI.read_bytes()[:2000],
    "parquet_magic_only": b"PAR1" + b"\x00" * 64 + b"PAR1",
    "json_array": b"[1, 2, 3]",
    "latin1": "time,station,range_m\n2026-03-20T09:30:00Z,K\xd8B,1\n".encode("latin-1"),
    "xml": b"<?xml version='1.0'?><tdm></tdm>",
}


def _make(tmp_path, kind):
    path = tmp_path / f"bad_{kind}"
    if BAD[kind] == "DIR":
        path.mkdir()
    elif BAD[kind] is not None:
        path.write_bytes(BAD[kind])
    return path


COMMANDS = {
    "ingest": lambda f, o: ["ingest", f, "--stations", STATIONS, "-o", o],
    "info": lambda f, o: ["info", f],
    "smooth": lambda f, o: ["smooth", f, "-o", o],
    "estimate": lambda f, o: ["estimate", f, "--initial", TRUTH, "-o", o],
    "refine": lambda f, o: ["refine", f, "--initial", TRUTH, "-o", o],
    "detect": lambda f, o: ["detect", f, "--nominal", NOMINAL, "-o", o],
    "propagate": lambda f, o: ["propagate", f, "--span", "600", "--step", "60", "-o", o],
    "accuracy": lambda f, o: ["accuracy", f, "--span", "600", "--step", "60", "-o", o],
    "simulate": lambda f, o: ["simulate", "--state", f, "--stations", STATIONS, "--duration", "60", "--step", "10",
                              "-o", o],
    "simulate-stations": lambda f, o: ["simulate", "--state", TRUTH, "--stations", f, "--duration", "60",
                                       "--step", "10", "-o", o],
    "estimate-initial": lambda f, o: ["estimate", MULTI, "--initial", f, "-o", o],
}


@pytest.mark.parametrize("kind", list(BAD))
@pytest.mark.parametrize("command", list(COMMANDS))
def test_wrong_file(run_cli, tmp_path, command, kind):
    bad = _make(tmp_path, kind)
    out = tmp_path / "out.parquet"   # a table suffix: the input, not the output, is what is wrong
    result = run_cli([*COMMANDS[command](bad, out), "--dut1", "0", "-q"] if command not in ("ingest", "info", "smooth")
                     else [*COMMANDS[command](bad, out), "-q"])
    assert_rejected(result, 2, f"bad_{kind}", outputs=[out], folder=tmp_path)


# info reads state files and TDMs too: a broken one is named by its missing field
@pytest.mark.parametrize("text, needle", [(b'{"epoch": "2026-03-20T09:30:00Z"}', "'frame'"),
                                          (b"station,lat_deg\nCPH,55\n", "column"),
                                          (b"CCSDS_TDM_VERS = 2.0\n", "META_START")])
def test_info_names_what_it_was_given(run_cli, write, text, needle):
    result = run_cli(["info", write("thing", text), "-q"])
    assert_rejected(result, 2, "thing", needle)
