"""Scenario table of ``trackproc estimate`` under mis-modelled passes (issue 13): simulated passes
with a known truth, one error the estimate does not model per scenario; the rule is "covers or
says so" (every state component and estimated bias within 4 sigma of the truth, or a verdict
``suspect``/``rejected``).

Used by ``test_estimate_mismodel.py``; run as a script for the table of docs/estimate.md:

    PYTHONPATH=src python tests/cli/mismodel_scenarios.py [seeds...]
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from trackproc.io.passfile import PassTable, read_pass_table, write_pass_table

C = 299792458.0
#: The multi-station set (as tests/cli/test_estimate_cli.py): 3 stations, 6 h, range + Doppler at 2.2 GHz.
STATE = {"epoch": "2026-03-20T09:30:00.000Z", "frame": "GCRF",
         "position_m": [3774841.0, -1538034.0, 5924146.0], "velocity_m_s": [-4816.6, 3936.4, 4091.1]}
GUESS = {**STATE, "position_m": [3775441.0, -1538534.0, 5924706.0], "velocity_m_s": [-4816.0, 3935.9, 4091.7]}
STATIONS = {"ZHY": (48.0, 35.0, 150.0), "KIR": (67.857, 20.964, 400.0), "MAD": (40.43, -4.25, 830.0)}
BIASES = {"ZHY": 100.0, "KIR": -80.0, "MAD": 120.0}
FREQ_OFFSET = 20.0
#: The VHF evening (DopTrack-like): a 600 km sun-synchronous-like orbit, one station at Delft,
#: one-way Doppler at 145.87 MHz, 1.5 Hz noise, a per-pass offset and drift.
VHF_STATE = {"epoch": "2026-03-20T17:00:00.000Z", "frame": "GCRF",
             "position_m": [-2180000.0, 1520000.0, 6420000.0], "velocity_m_s": [-1230.0, -7380.0, 1320.0]}
VHF_STATION = {"DLF": (51.99, 4.38, 30.0)}
VHF_CARRIER = 145.87e6
VHF_SIGMA_HZ = 1.5
#: The VHF a-priori on the first guess (like a TLE's: 1 km, 1 m/s), the guess drawn from it.
VHF_APRIORI = (1000.0, 1.0)


def _stations_csv(stations: dict, moved: dict | None = None) -> str:
    lines = ["station,lat_deg,lon_deg,height_m"]
    for name, (lat, lon, h) in stations.items():
        dn = (moved or {}).get(name, 0.0)          # metres north
        lines.append(f"{name},{lat + math.degrees(dn / 6371000.0):.9f},{lon},{h}")
    return "\n".join(lines) + "\n"


#: The command-line entry point the scenarios run (``trackproc.cli.app.main`` unless a test sets it).
RUNNER = None


def _cli(args) -> int:
    if RUNNER is None:
        from trackproc.cli import app as cli_app

        main = cli_app.main
    else:
        main = RUNNER
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            return main([str(a) for a in args])
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)


def _simulate(d: Path, name: str, state: dict, stations: dict, *extra) -> Path:
    (d / f"{name}.state.json").write_text(json.dumps(state))
    (d / f"{name}.stations.csv").write_text(_stations_csv(stations))
    out = d / f"{name}.parquet"
    code = _cli(["simulate", "--state", d / f"{name}.state.json", "--stations", d / f"{name}.stations.csv",
                 "--dut1", "0.1", "--truth", d / f"{name}.truth.json", "-o", out, *extra])
    assert code == 0, name
    return out


def _split(table: PassTable, rows) -> tuple[PassTable, PassTable]:
    rows = np.asarray(rows, bool)
    return (PassTable(table.frame[~rows].reset_index(drop=True), dict(table.meta)),
            PassTable(table.frame[rows].reset_index(drop=True), dict(table.meta)))


def _pass_rows(frame, station: str | None = None, index: int = 0, kind: str | None = None):
    """Rows of the ``index``-th pass (sorted ids) of ``station`` (of any station when None)."""
    sel = np.ones(len(frame), bool) if station is None else (frame["station"].astype(str) == station).to_numpy()
    ids = sorted(set(frame.loc[sel, "pass_id"].astype(str)))
    rows = sel & (frame["pass_id"].astype(str) == ids[index]).to_numpy()
    if kind is not None:
        rows &= (frame["kind"].astype(str) == kind).to_numpy()
    return rows, ids[index]


class Sets:
    """The simulated base sets of one noise draw (``seed``), made once in ``root``."""

    def __init__(self, root: Path, seed: int):
        self.d = Path(root)
        self.seed = seed
        self.d.mkdir(parents=True, exist_ok=True)
        self.multi = _simulate(self.d, "multi", STATE, STATIONS, "--duration", "21600", "--step", "30",
                               "--seed", seed, "--kinds", "range,doppler", "--freq-offset-hz", FREQ_OFFSET,
                               *sum((["--range-bias", f"{k}={v}"] for k, v in BIASES.items()), []))
        (self.d / "guess.json").write_text(json.dumps(GUESS))
        (self.d / "stations.csv").write_text(_stations_csv(STATIONS))
        # VHF evening: truth, an a-priori state around it, passes with per-pass offsets and drifts
        vhf = _simulate(self.d, "vhf", VHF_STATE, VHF_STATION, "--duration", "18000", "--step", "5",
                        "--seed", seed, "--kinds", "doppler", "--carrier-hz", VHF_CARRIER,
                        "--sigma-doppler-hz", VHF_SIGMA_HZ, "--elevation-mask-deg", "5")
        table = read_pass_table(str(vhf))
        rng = np.random.default_rng(1000 + seed)
        frame = table.frame.copy()
        ids = sorted(set(frame["pass_id"].astype(str)))
        self.vhf_offsets = {}
        for pid in ids:
            rows = (frame["pass_id"].astype(str) == pid).to_numpy()
            t = (frame.loc[rows, "time"] - frame.loc[rows, "time"].min()).dt.total_seconds().to_numpy()
            off, drift = rng.uniform(-800, 800), rng.uniform(-0.05, 0.05)
            frame.loc[rows, "value"] = frame.loc[rows, "value"].to_numpy() + off + drift * t
            self.vhf_offsets[pid] = (off, drift)
        self.vhf_ids = ids
        self.vhf = self.d / "vhf_biased.parquet"
        write_pass_table(PassTable(frame, table.meta), str(self.vhf))
        sig = np.r_[[VHF_APRIORI[0]] * 3, [VHF_APRIORI[1]] * 3]
        truth = np.r_[VHF_STATE["position_m"], VHF_STATE["velocity_m_s"]]
        guess = truth + rng.normal(size=6) * sig
        (self.d / "vhf_guess.json").write_text(json.dumps({**VHF_STATE, "position_m": list(guess[:3]),
                                                           "velocity_m_s": list(guess[3:]),
                                                           "parameters": ["x", "y", "z", "vx", "vy", "vz"],
                                                           "covariance": np.diag(sig ** 2).tolist()}))
        (self.d / "vhf_stations.csv").write_text(_stations_csv(VHF_STATION))

    def range_rate(self) -> Path:
        """The 3-station set with one-way range-rate (1 cm/s) instead of Doppler (made once)."""
        if not (self.d / "rr.parquet").exists():
            _simulate(self.d, "rr", STATE, STATIONS, "--duration", "21600", "--step", "30", "--seed", self.seed,
                      "--kinds", "range,range_rate",
                      *sum((["--range-bias", f"{k}={v}"] for k, v in BIASES.items()), []))
        return self.d / "rr.parquet"

    # -- scenario builders: each returns (pass files, estimate options, truth of the biases, named pass)
    def write(self, name: str, *tables: PassTable) -> list:
        paths = []
        for i, t in enumerate(tables):
            p = self.d / f"{name}.{i}.parquet"
            write_pass_table(t, str(p))
            paths.append(p)
        return paths


MULTI_OPTS = ("--range-bias", "--doppler-bias", "offset", "--dut1", "0.1")
RR_OPTS = ("--range-bias", "--dut1", "0.1")
#: The scenarios also run on the range-rate set (prefix ``rr_``).
RR = ("clean", "station_300", "timetag_0.5", "bias_jump", "range_step_20", "bias_jump_15")
VHF_OPTS = ("--doppler-bias", "offset+drift", "--apriori-initial", "--dut1", "0.1")


def scenario(sets: Sets, name: str):
    """``(files, initial, stations, options, truth dict, expected culprit or None)`` of one scenario."""
    d = sets.d
    rr = name.startswith("rr_")                           # the 3-station set with range-rate instead of Doppler
    if rr:
        name = name[3:]
        if name not in RR:
            raise KeyError(name)
    base_path = sets.range_rate() if rr else sets.multi
    base = read_pass_table(str(base_path))
    frame = base.frame
    truth = {f"range_bias:{k}": v for k, v in BIASES.items()}
    multi = dict(initial=d / "guess.json", stations=d / "stations.csv", options=RR_OPTS if rr else MULTI_OPTS,
                 truth=truth, state=d / "multi.truth.json")
    vt = {}
    for pid, (off, drift) in sets.vhf_offsets.items():
        vt[f"doppler_offset:{pid}"] = off
        vt[f"doppler_drift:{pid}"] = drift
    vhf = dict(initial=d / "vhf_guess.json", stations=d / "vhf_stations.csv", options=VHF_OPTS, truth=vt,
               state=d / "vhf.truth.json")
    vtab = read_pass_table(str(sets.vhf))
    if name == "clean":
        return dict(multi, files=[base_path], culprit=None)
    if name.startswith("station_"):                       # station_300 / station_1000: KIR moved north
        dn = float(name.split("_")[1])
        p = d / f"{name}.stations.csv"
        p.write_text(_stations_csv(STATIONS, {"KIR": dn}))
        return dict(multi, files=[base_path], stations=p, culprit="KIR")
    if name.startswith("timetag_"):                       # timetag_0.5 / timetag_2: KIR's time tags late
        dt = float(name.split("_")[1])
        f = frame.copy()
        rows = (f["station"].astype(str) == "KIR").to_numpy()
        f.loc[rows, "time"] = f.loc[rows, "time"] + pd.Timedelta(seconds=dt)
        return dict(multi, files=sets.write(("rr_" if rr else "") + name, PassTable(f, dict(base.meta))), culprit="KIR")
    if name == "bias_not_estimated":
        return dict(multi, files=[sets.multi], options=("--doppler-bias", "offset", "--dut1", "0.1"),
                    truth={}, culprit=None)
    if name.startswith("bias_jump"):                      # +50 m (bias_jump_M: M m) on KIR's second pass only
        f = frame.copy()
        rows, pid = _pass_rows(f, "KIR", 1, "range")
        f.loc[rows, "value"] = f.loc[rows, "value"].to_numpy() + (float(name.split("_")[2]) if name.count("_") == 2
                                                                  else 50.0)
        return dict(multi, files=sets.write(("rr_" if rr else "") + name, PassTable(f, dict(base.meta))), culprit=pid)
    if name.startswith("range_step_"):                    # +M m on the second half of KIR's second pass's ranges
        f = frame.copy()
        rows, pid = _pass_rows(f, "KIR", 1, "range")
        idx = np.flatnonzero(rows)
        f.loc[idx[idx.size // 2:], "value"] = f.loc[idx[idx.size // 2:], "value"].to_numpy() + float(name.split("_")[2])
        return dict(multi, files=sets.write(("rr_" if rr else "") + name, PassTable(f, dict(base.meta))), culprit=pid)
    if name == "carrier_3khz":                            # one pass's carrier labelled 3 kHz high
        rows, pid = _pass_rows(frame, "KIR", 1)
        rest, one = _split(base, rows)
        one.meta["carrier_hz"] = float(base.meta["carrier_hz"]) + 3000.0
        return dict(multi, files=sets.write(name, rest, one), culprit=pid)
    if name == "two_way_as_one_way":                      # one pass is two-way, labelled one-way
        two = _simulate(d, "twoway", STATE, STATIONS, "--duration", "21600", "--step", "30", "--seed",
                        sets.seed + 500, "--kinds", "range,doppler", "--freq-offset-hz", FREQ_OFFSET,
                        "--mode", "two-way", *sum((["--range-bias", f"{k}={v}"] for k, v in BIASES.items()), []))
        tw = read_pass_table(str(two))
        rows, pid = _pass_rows(frame, "KIR", 1)
        rows_tw = ((tw.frame["station"].astype(str) == "KIR") & (tw.frame["pass_id"].astype(str) == pid)).to_numpy()
        rest, _ = _split(base, rows)
        _, one = _split(tw, rows_tw)
        one.meta["doppler_mode"] = "one-way"
        return dict(multi, files=sets.write(name, rest, one), culprit=pid)
    if name == "other_satellite":                         # KIR's second pass is of a satellite 30 s behind
        later = {**STATE, "epoch": "2026-03-20T09:30:30.000Z"}
        other = _simulate(d, "other", later, STATIONS, "--start", STATE["epoch"], "--duration", "21600", "--step",
                          "30", "--seed", sets.seed + 700, "--kinds", "range,doppler", "--freq-offset-hz",
                          FREQ_OFFSET, *sum((["--range-bias", f"{k}={v}"] for k, v in BIASES.items()), []))
        ot = read_pass_table(str(other))
        rows, pid = _pass_rows(frame, "KIR", 1)
        t0, t1 = frame.loc[rows, "time"].min(), frame.loc[rows, "time"].max()
        of = ot.frame
        orow = ((of["station"].astype(str) == "KIR") & (of["time"] >= t0 - pd.Timedelta(seconds=60))
                & (of["time"] <= t1 + pd.Timedelta(seconds=60))).to_numpy()
        sub = of[orow].copy()
        sub["pass_id"] = pid
        f = pd.concat([frame[~rows], sub], ignore_index=True).sort_values("time", kind="stable").reset_index(drop=True)
        return dict(multi, files=sets.write(("rr_" if rr else "") + name, PassTable(f, dict(base.meta))), culprit=pid)
    if name.startswith("drag_"):                          # drag_1 / drag_3 (days): drag + SRP in the truth
        days = int(name.split("_")[1])
        sim = _simulate(d, name, STATE, STATIONS, "--duration", str(86400 * days), "--step", "60", "--seed",
                        sets.seed, "--kinds", "range,doppler", "--freq-offset-hz", FREQ_OFFSET, "--force", "full",
                        "--gravity", "2x0", "--third-body", "none", "--no-relativity", "--mass-kg", "100",
                        "--drag-area-m2", "2", "--srp-area-m2", "2",
                        *sum((["--range-bias", f"{k}={v}"] for k, v in BIASES.items()), []))
        return dict(multi, files=[sim], options=MULTI_OPTS + ("--force", "j2"), state=d / f"{name}.truth.json",
                    culprit=None)
    # VHF one-station evenings
    vf = vtab.frame
    if name == "vhf_clean":
        return dict(vhf, files=[sets.vhf], culprit=None)
    if name.startswith("vhf_station_"):
        dn = float(name.split("_")[2])
        p = d / f"{name}.stations.csv"
        p.write_text(_stations_csv(VHF_STATION, {"DLF": dn}))
        return dict(vhf, files=[sets.vhf], stations=p, culprit="DLF")
    if name.startswith("vhf_timetag_"):
        dt = float(name.split("_")[2])
        f = vf.copy()
        f["time"] = f["time"] + pd.Timedelta(seconds=dt)
        return dict(vhf, files=sets.write(name, PassTable(f, dict(vtab.meta))), culprit="DLF")
    if name == "vhf_carrier_3khz":
        rows, pid = _pass_rows(vf, None, 1)
        rest, one = _split(vtab, rows)
        one.meta["carrier_hz"] = VHF_CARRIER + 3000.0
        return dict(vhf, files=sets.write(name, rest, one), culprit=pid)
    if name.startswith("vhf_oscillator_step"):            # 20 Hz (_A: A Hz) thermal step, 60 s time constant, mid-pass 2
        f = vf.copy()
        rows, pid = _pass_rows(f, None, 1)
        t = (f.loc[rows, "time"] - f.loc[rows, "time"].min()).dt.total_seconds().to_numpy()
        ts = 0.5 * t.max()
        amp = float(name.split("_")[3]) if name.count("_") == 3 else 20.0
        f.loc[rows, "value"] = f.loc[rows, "value"].to_numpy() + np.where(t > ts, amp * (1 - np.exp(-(t - ts) / 60.0)), 0.0)
        return dict(vhf, files=sets.write(name, PassTable(f, dict(vtab.meta))), culprit=pid)
    if name == "vhf_other_satellite":                     # pass 2 is of a satellite 30 s behind
        later = {**VHF_STATE, "epoch": "2026-03-20T17:00:30.000Z"}
        other = _simulate(d, "vhf_other", later, VHF_STATION, "--start", VHF_STATE["epoch"], "--duration", "18000",
                          "--step", "5", "--seed", sets.seed + 700, "--kinds", "doppler", "--carrier-hz", VHF_CARRIER,
                          "--sigma-doppler-hz", VHF_SIGMA_HZ, "--elevation-mask-deg", "5")
        of = read_pass_table(str(other)).frame
        rows, pid = _pass_rows(vf, None, 1)
        t0, t1 = vf.loc[rows, "time"].min(), vf.loc[rows, "time"].max()
        orow = ((of["time"] >= t0 - pd.Timedelta(seconds=60)) & (of["time"] <= t1 + pd.Timedelta(seconds=60))).to_numpy()
        sub = of[orow].copy()
        tt = (sub["time"] - sub["time"].min()).dt.total_seconds().to_numpy()
        off, drift = sets.vhf_offsets[pid]
        sub["value"] = sub["value"].to_numpy() + off + drift * tt
        sub["pass_id"] = pid
        f = pd.concat([vf[~rows], sub], ignore_index=True).sort_values("time", kind="stable").reset_index(drop=True)
        return dict(vhf, files=sets.write(name, PassTable(f, dict(vtab.meta))), culprit=pid)
    raise KeyError(name)


MULTI = ["clean", "station_300", "station_1000", "timetag_0.5", "timetag_2", "bias_not_estimated", "bias_jump",
         "carrier_3khz", "two_way_as_one_way", "other_satellite"]
VHF = ["vhf_clean", "vhf_station_1000", "vhf_timetag_0.5", "vhf_timetag_2", "vhf_carrier_3khz",
       "vhf_oscillator_step", "vhf_other_satellite"]
DYNAMICS = ["drag_1", "drag_3"]
#: Near the detection limits: smaller versions of the same errors.
SMALL = ["station_100", "timetag_0.05", "bias_jump_15", "range_step_20", "vhf_station_300", "vhf_oscillator_step_10",
         "vhf_oscillator_step_5"]
ALL = MULTI + VHF + DYNAMICS + SMALL + ["rr_" + n for n in RR]


def run(sets: Sets, name: str, *extra) -> dict:
    """Estimate one scenario: exit code, verdict, reasons not ok, max |z| over the state and the
    estimated biases with a truth, and whether the culprit is named."""
    sc = scenario(sets, name)
    out = sets.d / f"{name}.sol.json"
    if out.exists():
        out.unlink()
    code = _cli(["estimate", *sc["files"], "--initial", sc["initial"], "--stations", sc["stations"],
                 *sc["options"], "--strict", "-o", out, *extra])
    row = {"scenario": name, "exit": code}
    if not out.exists():
        row.update(verdict="(failed)", reasons="", z_state=math.nan, z_bias=math.nan, named=None)
        return row
    doc = json.loads(out.read_text())
    truth = json.loads(Path(sc["state"]).read_text())
    err = np.asarray(doc["values"][:6], float) - np.r_[truth["position_m"], truth["velocity_m_s"]]
    sig = np.asarray(doc["sigma"][:6], float)
    zb = [abs(doc["values"][i] - sc["truth"][p]) / doc["sigma"][i] for i, p in enumerate(doc["parameters"])
          if p in sc["truth"] and doc["sigma"][i] > 0]
    q = doc["quality"]
    bad = [r for r in q["reasons"] if r["severity"] != "ok"]
    # the culprit named: in the pass-consistency reason's first block, else in the dominant pass's
    named = [r["message"].split(": ", 1)[-1].split(" (")[0] for r in bad if r["code"] == "pass_consistency"]
    named += [r["message"].split(" carries")[0] for r in bad if r["code"] == "dominant_pass"]
    named += [r["message"].split(": ", 1)[-1] for r in bad if r["code"] == "edited_pass"]
    named += [r["message"].split(":")[0].removeprefix("pass ") for r in bad if r["code"] == "step"]
    text = named[0] if named else ""
    row.update(verdict=q["verdict"], reasons=",".join(r["code"] for r in bad), z_state=float(np.max(np.abs(err / sig))),
               z_bias=float(max(zb)) if zb else 0.0,
               named=(sc["culprit"] in text) if sc["culprit"] and text else None, first_named=text, doc=doc)
    return row


def covers_or_says_so(row: dict) -> bool:
    z = max(row["z_state"], row["z_bias"])
    return row["verdict"] in ("suspect", "rejected", "(failed)") or z < 4.0


if __name__ == "__main__":
    import tempfile

    seeds = [int(s) for s in sys.argv[1:] if s.isdigit()] or [1]
    names = [s for s in sys.argv[1:] if not s.isdigit()] or ALL
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            sets = Sets(Path(tmp) / f"s{seed}", seed)
            for name in names:
                r = run(sets, name)
                print(f"seed {seed:3d} {name:22s} exit {r['exit']} {r['verdict']:9s} z_state {r['z_state']:8.2f} "
                      f"z_bias {r['z_bias']:8.2f} named {r['named']!s:5s} {r.get('first_named', '')!s:18s} {r['reasons']}", flush=True)
