"""``trackproc filter`` through the command line: the docs' example on the shipped three-station set
against the truth it was simulated from (``sample_data/truth_at_start.json`` and the range biases
of ``sample_data/make.sh``). The filter's own references (estimate's batch solution, a manoeuvre,
a carried state) are in tests/pipeline/test_filter.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
#: the range biases sample_data/make.sh simulated (m)
BIASES = {"range_bias:CPH": 120.0, "range_bias:KIR": 45.0, "range_bias:ZHY": -80.0}


def test_smoothed_state_and_biases_cover_the_simulated_truth(run_cli, tmp_path):
    out, oem_path = tmp_path / "smoothed.json", tmp_path / "history.oem"
    result = run_cli(["filter", SAMPLE / "multistation.parquet", "--initial", SAMPLE / "stale.json",
                      "--range-bias", "--apriori-sigma", "range_bias=1000", "--kinds", "range,range_rate",
                      "--smooth", "--iterations", "5", "--history", oem_path, "--object-name", "SEED",
                      "-q", "-o", out])
    assert result.exit_code == 0, result.stderr
    state = json.loads(out.read_text())
    truth = json.loads((SAMPLE / "truth_at_start.json").read_text())
    assert state["epoch"] == truth["epoch"]                        # smoothed back to the first time
    expected = dict(zip(truth["parameters"], truth["values"]), **BIASES)
    assert set(state["parameters"]) == set(expected)
    z = [(v - expected[n]) / s for n, v, s in zip(state["parameters"], state["values"], state["sigma"])]
    assert np.max(np.abs(z)) < 4.0, dict(zip(state["parameters"], z))
    # the stale first guess was 10 km away: the data moved it
    stale = json.loads((SAMPLE / "stale.json").read_text())
    assert np.linalg.norm(np.subtract(stale["position_m"], truth["position_m"])) > 1000.0
    # --history as CCSDS OEM: a filtered and a smoothed segment, a covariance block per step; the
    # smoothed block at the epoch is the state file's covariance (km**2 ...), its line the state
    oem = parse_oem(oem_path.read_text())
    assert oem["header"]["CCSDS_OEM_VERS"] == "2.0" and len(oem["segments"]) == 2
    filtered, smoothed = oem["segments"]
    assert filtered["meta"]["OBJECT_NAME"] == "SEED" and filtered["meta"]["REF_FRAME"] == "GCRF"
    assert len(filtered["lines"]) == len(smoothed["lines"]) == len(smoothed["covariances"]) > 100
    assert [t for t, _ in filtered["lines"]] == [c["epoch"] for c in filtered["covariances"]]
    first_t, first = smoothed["lines"][0]
    assert first_t == np.datetime64(state["epoch"].rstrip("Z"), "ns")
    np.testing.assert_allclose(np.multiply(first, 1000.0), state["position_m"] + state["velocity_m_s"], rtol=1e-12)
    cov6 = np.asarray(state["covariance"])[:6, :6]
    np.testing.assert_allclose(smoothed["covariances"][0]["matrix"] * 1e6, cov6, rtol=1e-9,
                               atol=1e-12 * np.abs(cov6).max())
    # the filter's last covariance is smaller than its first (the data reduced it)
    assert np.trace(filtered["covariances"][-1]["matrix"][:3, :3]) < np.trace(filtered["covariances"][0]["matrix"][:3, :3])


def parse_oem(text: str) -> dict:
    """A small CCSDS OEM KVN reader (CCSDS 502.0-B-3 5.2): header, then segments of a META block,
    data lines ``epoch x y z vx vy vz`` and an optional covariance section of lower triangles."""
    header, segments = {}, []
    section, seg, cov = "header", None, None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("COMMENT"):
            continue
        if line == "META_START":
            seg = {"meta": {}, "lines": [], "covariances": []}
            segments.append(seg)
            section = "meta"
        elif line in ("META_STOP", "COVARIANCE_START", "COVARIANCE_STOP"):
            section = {"META_STOP": "data", "COVARIANCE_START": "cov", "COVARIANCE_STOP": "after"}[line]
        elif section in ("header", "meta"):
            key, _, value = line.partition("=")
            (header if section == "header" else seg["meta"])[key.strip()] = value.strip()
        elif section == "data":
            parts = line.split()
            assert len(parts) == 7, line
            seg["lines"].append((np.datetime64(parts[0], "ns"), [float(p) for p in parts[1:]]))
        elif section == "cov":
            if line.startswith("EPOCH"):
                cov = {"epoch": np.datetime64(line.split("=")[1].strip(), "ns"), "rows": []}
                seg["covariances"].append(cov)
            elif line.startswith("COV_REF_FRAME"):
                cov["frame"] = line.split("=")[1].strip()
            else:
                cov["rows"].append([float(p) for p in line.split()])
    for seg in segments:
        for c in seg["covariances"]:
            m = np.zeros((6, 6))
            for i, row in enumerate(c["rows"]):
                assert len(row) == i + 1
                m[i, :i + 1] = row
            c["matrix"] = m + np.tril(m, -1).T
    return {"header": header, "segments": segments}


def _one_pass_and_state(tmp_path, offset_m: float, sigma=(10.0, 0.01)):
    """The shipped set's first pass (ZHY, 100 range + range-rate samples) as a pass file, and a
    state file: the truth moved ``offset_m`` along-track with a stated covariance ``sigma``."""
    from trackproc.io.passfile import PassTable, read_pass_table, write_pass_table
    from trackproc.io.statefile import read_state, state_json
    from trackproc.types.state import State

    table = read_pass_table(str(SAMPLE / "multistation.parquet"))
    frame = table.frame
    first = frame.groupby(["station", "pass_id"])["time"].min().sort_values().index[0]
    sel = ((frame["station"] == first[0]) & (frame["pass_id"] == first[1])).to_numpy()
    passes = tmp_path / "one.parquet"
    write_pass_table(PassTable(frame[sel].reset_index(drop=True), table.meta), str(passes))
    truth = read_state(str(SAMPLE / "truth_at_start.json"), None)
    sig = np.array([sigma[0]] * 3 + [sigma[1]] * 3)
    rv = truth.rv + np.concatenate([offset_m * truth.v_m_s / np.linalg.norm(truth.v_m_s), np.zeros(3)])
    state = tmp_path / f"initial_{offset_m:g}.json"
    state.write_text(state_json(State.from_vectors(truth.epoch, rv[:3], rv[3:], values=rv, sigma=sig,
                                                   covariance=np.diag(sig ** 2))))
    return passes, state


def test_declined_prior_exits_0_and_1_with_strict(run_cli, tmp_path):
    """A pass that contradicts a stated prior (500 m along-track off, 10 m / 1 cm/s: 50 sigma) is
    declined: the prior written with its covariance, verdict suspect with reason ``declined``,
    exit 0, and 1 with ``--strict`` (the file written either way); ``--horizon`` reaches the
    replace-or-keep rule of a consistent prior (the truth, 100 m / 0.1 m/s)."""
    passes, bad = _one_pass_and_state(tmp_path, 500.0)
    args = ["filter", passes, "--initial", bad, "--range-bias", "--apriori-sigma", "range_bias=1000",
            "--kinds", "range,range_rate", "--noise", "white",
            "--edit-sigma", "0", "--force", "j2"]
    for strict, code in ((False, 0), (True, 1)):
        out = tmp_path / f"declined_{strict}.json"
        result = run_cli(args + (["--strict"] if strict else []) + ["-o", out])
        assert result.exit_code == code, result.stderr
        state = json.loads(out.read_text())
        decision = state["diagnostics"]["decision"]
        assert decision["action"] == "declined" and decision["apriori_source"] == "stated", decision
        assert state["quality"]["verdict"] == "suspect"
        assert "declined" in [r["code"] for r in state["quality"]["reasons"]]
        assert "declined: " in result.stderr
        assert state["estimation"]["apriori_source"] == "stated"
    _, good = _one_pass_and_state(tmp_path, 0.0, sigma=(100.0, 0.1))
    out = tmp_path / "horizon.json"
    result = run_cli(["filter", passes, "--initial", good, "--range-bias", "--apriori-sigma", "range_bias=1000",
                      "--kinds", "range,range_rate", "--noise", "white",
                      "--force", "j2", "--horizon", "2", "-q", "-o", out])
    assert result.exit_code == 0, result.stderr
    decision = json.loads(out.read_text())["diagnostics"]["decision"]
    assert decision["action"] in ("kept", "replaced") and decision["horizon_days"] == 2.0, decision
