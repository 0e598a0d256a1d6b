"""``trackproc batch``: 30 simulated passes (5 broken) through ingest -> smooth, cron-grade.

One simulated day (six stations, one-way Doppler and elevation, noise) is split into one wide
CSV per pass, as stations write them; five more inputs are broken in the ways a nightly run
meets: a bad CSV, an unknown station, too few points for the smoother, a pass the smoother
cannot fit (its clock froze: 24 samples inside 24 ns), and a Parquet file cut in half by a
transfer.

The refine step runs on the seed 004 Table 1 geometry (``refine_passes``): passes over stations
placed so that the truth state is their traverse point, refined from the stale state.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from once_per_run import once_per_run
from trackproc.pipeline import batch as batch_module
from trackproc.pipeline.batch.schema import SCHEMA

ROOT = Path(__file__).resolve().parents[2]
STATIONS = ("station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\nZHY,50.25,28.66,230\nKIR,67.857,20.964,400\n"
            "MAD,40.43,-4.25,800\nSVB,78.23,15.4,500\nHBK,-25.89,27.69,1500\n")
BROKEN = {  # input name -> what its error must say
    "broken_bad_csv": "row 2, column 'time'",
    "broken_unknown_station": "unknown station; found 'XYZ'",
    "broken_too_few_points": "no pass could be fitted",
    "broken_frozen_clock": "not determined by the sample times",
    "broken_truncated": "parquet",
}
GOOD = 25


@pytest.fixture(scope="session")
def passes(tmp_path_factory) -> Path:
    """``inbox/`` with 25 good passes and 5 broken ones, ``stations.csv``, ``stale.json``; made once
    per test run (the xdist workers share it: tests only read it)."""
    return once_per_run(tmp_path_factory, "batch_passes", _make_passes)["dir"]


def _make_passes(root: Path) -> dict:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from trackproc.io.stations import parse_stations
    from trackproc.io.statefile import read_state
    from trackproc.pipeline.simulate import SimulateOptions, simulate

    inbox = root / "inbox"
    inbox.mkdir()
    (root / "stations.csv").write_text(STATIONS)
    shutil.copy(ROOT / "sample_data" / "stale.json", root / "stale.json")
    sim = simulate(read_state(str(ROOT / "sample_data" / "truth.json")), parse_stations(STATIONS.encode(), "st"),
                   SimulateOptions(duration_s=86400, step_s=10, kinds=("doppler", "elevation"), seed=1,
                                   sigma_doppler_hz=0.5))
    wide = sim.wide()
    frame = sim.frame
    sizes = frame.groupby(["station", "pass_id"]).size()
    keys = [k for k in sizes.index if sizes[k] >= 100]
    assert len(keys) >= GOOD + 1

    def rows(station, pass_id):
        times = frame.loc[(frame["station"] == station) & (frame["pass_id"] == pass_id), "time"].unique()
        sub = wide[(wide["station"] == station) & wide["time"].isin(times)]
        return sub.assign(time=sub["time"].dt.strftime("%Y-%m-%dT%H:%M:%SZ"))

    for i, (station, pass_id) in enumerate(keys[:GOOD]):
        table = rows(station, pass_id)
        if i == 0:  # a column ingest does not know: a warning (logged by the reader), not an error
            table = table.assign(snr_db=12.5)
        table.to_csv(inbox / f"{pass_id}.csv", index=False)
    spare = rows(*keys[GOOD])
    (inbox / "broken_bad_csv.csv").write_text("time,station,doppler_hz\nnot-a-time,CPH,12.0\n")
    spare.assign(station="XYZ").to_csv(inbox / "broken_unknown_station.csv", index=False)
    spare.head(1).to_csv(inbox / "broken_too_few_points.csv", index=False)
    frozen = spare[["time", "station", "doppler_hz"]].head(25).copy()
    frozen.iloc[:24, 0] = [frozen.iloc[0, 0][:-1] + f".{i:09d}Z" for i in range(24)]
    frozen.to_csv(inbox / "broken_frozen_clock.csv", index=False)
    sink = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_pandas(spare, preserve_index=False), sink)
    data = sink.getvalue().to_pybytes()
    (inbox / "broken_truncated.parquet").write_bytes(data[: len(data) // 2])
    return {"dir": root}


@pytest.fixture(autouse=True, scope="module")
def figures_drawn_once():
    """report.html's window figures drawn once per content: the tests here run a batch several times
    over the same inputs (a re-run, --force, a changed setting), and every run rewrites report.html
    with the same figures (matplotlib, ~1 s of CPU a run). A figure is a function of what it plots (a
    window's residuals file), so the bytes drawn first are the bytes a re-run draws. The overview is
    an SVG written as text (milliseconds): drawn each time. The report itself is tested in
    tests/cli/test_batch_report.py, tests/report/test_batch_svg.py and test_report_plots.py."""
    from trackproc.report import batch_html

    drawn: dict = {}
    window_png = batch_html.window_png

    def window_once(out, record):
        rel = next((o for o in record.get("outputs") or [] if o.endswith(".residuals.parquet")), None)
        if rel is None or not (out / rel).is_file():
            return window_png(out, record)
        key = ("window", hashlib.sha256((out / rel).read_bytes()).hexdigest())
        if key not in drawn:
            drawn[key] = window_png(out, record)
        return drawn[key]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(batch_html, "window_png", window_once)
        yield


def write_config(path: Path, passes: Path, output: Path, **sections) -> Path:
    """A config file; relative paths in it are relative to its directory (here: absolute)."""
    doc = {"batch": {"inputs": [str(passes / "inbox")], "output": str(output), "workers": 1},
           "ingest": {"stations": str(passes / "stations.csv"), "carrier_hz": 2.2e9, "mode": "one-way"}}
    for section, values in sections.items():
        doc.setdefault(section, {}).update(values)
    lines = []
    for section, values in doc.items():
        lines.append(f"[{section}]")
        lines.extend(f"{key} = {json.dumps(value)}" for key, value in values.items())
        lines.append("")
    path.write_text("\n".join(lines))
    return path


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def by_name(out: Path) -> dict:
    return {r["name"]: r for r in summary(out)["inputs"]}


def digest(out: Path) -> dict:
    """SHA-256 of every result file (not the manifests, summaries and report, which hold run times)."""
    return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(out.rglob("*")) if p.is_file() and not p.name.endswith(".batch.json")
            and not p.name.startswith(("summary.", "report.", "."))}


def comparable(record: dict) -> dict:
    return {k: v for k, v in record.items() if k not in ("seconds", "skipped")}


def mtimes(out: Path) -> dict:
    return {str(p): p.stat().st_mtime_ns for p in sorted((out / "passes").iterdir())}


# ----------------------------------------------------------------------------- the done-when run

@pytest.fixture(scope="module")
def thirty_in_a_pool(passes, tmp_path_factory, run_cli_shared):
    """(output directory, result) of the 30 inputs through a pool of two workers, run once for the
    module: the done-when test's first run and the pool side of the Dask comparison are the same
    command on the same inputs (each checks its own things of it; neither writes to it)."""
    root = tmp_path_factory.mktemp("thirty_pool")
    config = write_config(root / "nightly.toml", passes, root / "out")
    return root / "out", run_cli_shared(["batch", config, "--workers", "2"])


def test_thirty_passes_five_broken_then_rerun_skips_then_force_redoes(passes, tmp_path, run_cli, thirty_in_a_pool):
    shared, first = thirty_in_a_pool
    out = tmp_path / "out"
    shutil.copytree(shared, out)                  # the first run's results; the re-runs below change this copy
    config = write_config(tmp_path / "nightly.toml", passes, out)
    assert first.exit_code == 3, first.stderr
    assert "Traceback" not in first.stderr
    records = by_name(out)
    assert len(records) == 30
    ok = [n for n, r in records.items() if r["status"] == "ok"]
    failed = {n: r for n, r in records.items() if r["status"] == "failed"}
    assert len(ok) == GOOD and sorted(failed) == sorted(BROKEN)
    for name, text in BROKEN.items():
        assert text in failed[name]["error"], (name, failed[name]["error"])
        assert f"{name}: failed: " in first.stderr
    assert failed["broken_frozen_clock"]["error_type"] == "processing"
    assert failed["broken_bad_csv"]["error_type"] == "input"
    for name in ok:
        assert (out / "passes" / f"{name}.parquet").exists() and (out / "passes" / f"{name}.smooth.json").exists()
        numbers = records[name]["numbers"]
        assert numbers["kind"] == "doppler" and 0.2 < numbers["rms"] < 0.7 and numbers["rms_unit"] == "Hz"
        assert numbers["tca_utc"].endswith("Z") and 0 < numbers["tca_sigma_s"] < 0.2
        assert abs(numbers["fca_hz"] - 2.2e9) < 2e3
    for name in BROKEN:
        assert not (out / "passes" / f"{name}.parquet").exists()
    first_good = sorted(ok)[0]
    assert any("ignoring column 'snr_db'" in w for w in records[first_good]["warnings"])
    assert f"WARNING: {first_good}: " in first.stderr and "ignoring column 'snr_db'" in first.stderr
    counts = summary(out)["counts"]
    assert counts["inputs_ok"] == GOOD and counts["inputs_failed"] == 5 and counts["inputs_skipped"] == 0
    csv_lines = (out / "summary.csv").read_text().splitlines()
    assert len(csv_lines) == 31 and csv_lines[0].startswith("task,input,status,skipped,samples")
    assert any(line.startswith("pass,broken_unknown_station,failed,") and "XYZ" in line for line in csv_lines)

    # a re-run skips everything (the recorded failures too: their data did not change)
    before = mtimes(out)
    second = run_cli(["batch", config, "--workers", "2"])
    assert second.exit_code == 3, second.stderr
    assert "30 input(s): 30 up to date, 0 to do" in second.stderr
    assert all(r["skipped"] for r in by_name(out).values())
    assert mtimes(out) == before
    assert {n: comparable(r) for n, r in by_name(out).items()} == {n: comparable(r) for n, r in records.items()}

    # --force redoes everything, with the same results
    third = run_cli(["batch", config, "--workers", "2", "--force"])
    assert third.exit_code == 3
    assert "30 to do" in third.stderr
    assert not any(r["skipped"] for r in by_name(out).values())
    after = mtimes(out)
    assert all(after[p] != before[p] for p in before if p.endswith(".parquet"))


def test_changing_the_config_or_an_input_redoes_only_what_it_touches(passes, tmp_path, run_cli, monkeypatch):
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    for path in (passes / "inbox").glob("[CHK]*.csv"):
        shutil.copy(path, inbox)
    n = len(list(inbox.iterdir()))
    out = tmp_path / "out"
    config = write_config(tmp_path / "b.toml", passes, out, batch={"inputs": ["inbox"]})
    assert run_cli(["batch", config]).exit_code == 0
    # run settings (workers, log) are not part of the content key
    run = run_cli(["batch", config, "--workers", "2"])
    assert run.exit_code == 0 and f"{n} up to date, 0 to do" in run.stderr
    # one input changed: only it is redone
    victim = sorted(inbox.glob("*.csv"))[3]
    lines = victim.read_text().splitlines()
    victim.write_text("\n".join(lines[:-1]) + "\n")
    run = run_cli(["batch", config])
    assert run.exit_code == 0 and f"{n - 1} up to date, 1 to do" in run.stderr
    assert [n for n, r in by_name(out).items() if not r["skipped"]] == [victim.stem]
    # a step setting changed (here through the environment): everything is redone
    monkeypatch.setenv("TRACKPROC_BATCH_SMOOTH_CLIP", "5")
    run = run_cli(["batch", config])
    assert run.exit_code == 0 and f"0 up to date, {n} to do" in run.stderr
    monkeypatch.delenv("TRACKPROC_BATCH_SMOOTH_CLIP")
    run = run_cli(["batch", config])
    assert run.exit_code == 0 and f"0 up to date, {n} to do" in run.stderr  # clip back to 4: redone
    # the stations table's content (not its path) is part of the key
    stations = tmp_path / "moved_stations.csv"
    stations.write_text(STATIONS)
    run = run_cli(["batch", config, "--stations", stations])
    assert run.exit_code == 0 and f"{n} up to date, 0 to do" in run.stderr
    stations.write_text(STATIONS.replace("CPH,55.7", "CPH,55.8"))
    run = run_cli(["batch", config, "--stations", stations])
    assert f"0 up to date, {n} to do" in run.stderr
    # an input that now fails loses its old results (they would contradict the summary)
    victim.write_text("time,station,doppler_hz\n")
    run = run_cli(["batch", config, "--stations", stations])
    assert run.exit_code == 3
    assert not (out / "passes" / f"{victim.stem}.parquet").exists()
    assert by_name(out)[victim.stem]["status"] == "failed"


def test_dask_cluster_and_process_pool_give_the_serial_results(passes, tmp_path, run_cli, thirty_in_a_pool):
    distributed = pytest.importorskip("distributed")
    config = write_config(tmp_path / "b.toml", passes, tmp_path / "unused")
    serial, dask = tmp_path / "serial", tmp_path / "dask"
    pool, pool_run = thirty_in_a_pool                 # the pool of two workers: the done-when test's first run
    # the serial reference runs as a user runs it (a fresh process: one BLAS thread, as in the workers)
    exe = Path(sys.executable).with_name("trackproc")
    run = subprocess.run([str(exe), "batch", str(config), "-o", str(serial), "--workers", "1"], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 3, run.stderr
    assert pool_run.exit_code == 3
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        run = run_cli(["batch", config, "-o", dask, "--scheduler", cluster.scheduler_address])
    assert run.exit_code == 3, run.stderr
    assert "Dask scheduler tcp://127.0.0.1:" in run.stderr
    reference = digest(serial)
    assert len(reference) == 2 * GOOD
    assert digest(pool) == reference
    assert digest(dask) == reference
    want = {n: comparable(r) for n, r in by_name(serial).items()}
    assert {n: comparable(r) for n, r in by_name(pool).items()} == want
    assert {n: comparable(r) for n, r in by_name(dask).items()} == want


def test_scheduler_without_dask_installed_is_a_usage_error(passes, tmp_path, run_cli, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    config = write_config(tmp_path / "b.toml", passes, tmp_path / "out")
    run = run_cli(["batch", config, "--scheduler", "tcp://127.0.0.1:8786"])
    assert run.exit_code == 2
    assert "--scheduler needs Dask distributed, which is not installed" in run.stderr
    assert "pip install 'trackproc[dask]'" in run.stderr
    assert "Traceback" not in run.stderr


# ----------------------------------------------------------------------------- the lock

def _hold(lock: Path):
    lock.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(lock, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    os.write(fd, b"pid 12345 on testhost since 2026-01-01T00:00:00Z\n")
    return fd


def test_lock_blocks_a_second_run_or_makes_it_wait(passes, tmp_path, run_cli):
    out = tmp_path / "out"
    config = write_config(tmp_path / "b.toml", passes, out, batch={"inputs": [str(passes / "inbox" / "CPH*.csv")]})
    fd = _hold(out / ".batch.lock")
    try:
        run = run_cli(["batch", config])
        assert run.exit_code == 1
        assert "is held by another trackproc batch run (pid 12345 on testhost" in run.stderr
        assert "--wait" in run.stderr and "Traceback" not in run.stderr
        assert not (out / "summary.json").exists() and not (out / "passes").exists()
        run = run_cli(["batch", config, "--wait", "--wait-timeout", "0.3"])
        assert run.exit_code == 1 and "still held" in run.stderr
        threading.Timer(0.5, os.close, [fd]).start()
        fd = None
        run = run_cli(["batch", config, "--wait"])
        assert run.exit_code == 0, run.stderr
        assert "waiting for" in run.stderr
    finally:
        if fd is not None:
            os.close(fd)


def test_two_overlapping_runs_do_not_corrupt_each_other(passes, tmp_path):
    out = tmp_path / "out"
    config = write_config(tmp_path / "b.toml", passes, out, batch={"inputs": [str(passes / "inbox" / "[CK]*.csv")]})
    exe = Path(sys.executable).with_name("trackproc")
    cmd = [str(exe), "batch", str(config), "--wait"]
    first = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    second = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    logs = [p.communicate(timeout=120)[1] for p in (first, second)]
    assert [first.returncode, second.returncode] == [0, 0], logs
    n = len(by_name(out))
    assert n == len(list((passes / "inbox").glob("[CK]*.csv")))
    # one did the work, the other waited and then found everything up to date
    assert sorted(f"{n} up to date, 0 to do" in log for log in logs) == [False, True]


def test_a_write_probe_removed_by_a_running_batch_is_no_error(passes, tmp_path, run_cli, monkeypatch):
    """The output's write probe is made before the lock; a run holding the lock removes temporary
    files as leftovers of an interrupted run, the probe among them, between its write and its
    removal (the race seen once in CI with two overlapping runs): the second run goes on."""
    from trackproc.pipeline.batch import store

    out = tmp_path / "out"
    config = write_config(tmp_path / "b.toml", passes, out, batch={"inputs": [str(passes / "inbox" / "C*.csv")]})
    real_write = Path.write_bytes

    def write_then_removed(path, data):
        written = real_write(path, data)
        if path.name.startswith(".write-test-"):
            store.remove_leftovers(path.parent)              # the other run, under its lock
        return written

    monkeypatch.setattr(Path, "write_bytes", write_then_removed)
    run = run_cli(["batch", config, "--workers", "1"])
    assert run.exit_code == 0, run.stderr
    assert not list(out.glob(".write-test-*"))


def test_a_killed_run_resumes_where_it_stopped(passes, tmp_path):
    import signal

    out = tmp_path / "out"
    config = write_config(tmp_path / "b.toml", passes, out, batch={"inputs": [str(passes / "inbox" / "[A-Z]*.csv")]})
    exe = Path(sys.executable).with_name("trackproc")
    proc = subprocess.Popen([str(exe), "batch", str(config), "--workers", "1"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while len(list((out / "passes").glob("*.batch.json"))) < 3 and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)  # no clean-up at all, as a power cut or the OOM killer
    proc.wait()
    done = len(list((out / "passes").glob("*.batch.json")))
    assert 3 <= done < GOOD and not (out / "summary.json").exists()
    exe_run = subprocess.run([str(exe), "batch", str(config)], capture_output=True, text=True, timeout=120)
    assert exe_run.returncode == 0, exe_run.stderr
    skipped = sum(r["skipped"] for r in by_name(out).values())
    assert skipped >= done and len(by_name(out)) == GOOD
    assert not list(out.rglob(".*.tmp"))  # no temporary file of the killed run is left


# ----------------------------------------------------------------------------- settings

def test_settings_precedence_flag_env_config_default(tmp_path):
    from trackproc.pipeline.batch.config import resolve

    config = tmp_path / "c.toml"
    config.write_text('[batch]\nworkers = 3\ninputs = ["in"]\n[smooth]\nclip = 5.0\ndegree = 8\n')
    env = {"TRACKPROC_BATCH_WORKERS": "4", "TRACKPROC_BATCH_SMOOTH_DEGREE": "auto"}
    s = resolve(str(config), {"batch.workers": 5}, env)
    assert s.get("batch.workers") == 5 and s.origins["batch.workers"] == "flag"
    s = resolve(str(config), {}, env)
    assert s.get("batch.workers") == 4 and s.origins["batch.workers"] == "env"
    assert s.get("smooth.degree") == "auto" and s.origins["smooth.degree"] == "env"
    s = resolve(str(config), {}, {})
    assert s.get("batch.workers") == 3 and s.get("smooth.clip") == 5.0 and s.get("smooth.degree") == 8
    assert s.get("batch.inputs") == (str(tmp_path / "in"),)  # relative to the config file
    assert s.get("ingest.max_gap_s") == 300.0 and s.origins["ingest.max_gap_s"] == "default"
    s = resolve(None, {}, {"TRACKPROC_BATCH_CONFIG": str(config), "TRACKPROC_BATCH_INPUTS": "a,b",
                           "TRACKPROC_BATCH_ESTIMATE_APRIORI_SIGMA": "x=1000,vx=1",
                           "TRACKPROC_BATCH_FORCE": "yes"})
    assert s.get("batch.workers") == 3 and s.get("batch.inputs") == ("a", "b")  # env paths: as given
    assert s.get("estimate.apriori_sigma") == {"x": 1000.0, "vx": 1.0} and s.get("batch.force") is True
    # refine: "none" is a Doppler bias model there (the default is auto); apriori unset = by cost
    assert s.get("refine.doppler_bias") == "auto" and s.get("refine.apriori") is None
    config.write_text('[refine]\ndoppler_bias = "none"\napriori = false\n')
    s = resolve(str(config), {}, {"TRACKPROC_BATCH_REFINE_OUTPUT_EPOCH": "stale"})
    assert s.get("refine.doppler_bias") == "none" and s.get("refine.apriori") is False
    assert s.get("refine.output_epoch") == "stale" and s.origins["refine.output_epoch"] == "env"


@pytest.mark.parametrize("text, env, message", [
    ('[smooth]\nclipp = 3\n', {}, "smooth.clipp': unknown setting; expected one of degree"),
    ('[smoth]\n', {}, "did you mean smooth?"),
    ('[smooth]\nclip = "x"\n', {}, "column 'smooth.clip': invalid setting; found 'x'; expected a number"),
    ('[batch]\nworkers = -1\n', {}, "expected an integer >= 0"),
    ('[ingest]\nmode = "3-way"\n', {}, "expected one-way or two-way"),
    ('[batch\n', {}, "invalid TOML"),
    ('', {"TRACKPROC_BATCH_WORKER": "2"}, "column 'TRACKPROC_BATCH_WORKER': unknown environment variable"),
    ('', {"TRACKPROC_BATCH_WORKERS": "many"}, "column 'TRACKPROC_BATCH_WORKERS': invalid setting; found 'many'"),
])
def test_bad_settings_are_usage_errors_naming_the_key(tmp_path, run_cli, monkeypatch, text, env, message):
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    config = tmp_path / "c.toml"
    config.write_text(text)
    run = run_cli(["batch", config, "-o", tmp_path / "out", "-i", tmp_path])
    assert run.exit_code == 2
    assert message in run.stderr, run.stderr
    assert "Traceback" not in run.stderr


@pytest.mark.parametrize("args, message", [
    (["-i", "{inbox}"], "no output directory"),
    (["-o", "{tmp}/out"], "no inputs"),
    (["-i", "{tmp}/nowhere", "-o", "{tmp}/out"], "nowhere: input not found"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--steps", "ingest,smooth,refine"], "the refine step needs a stale state"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--steps", "ingest,refine", "--refine-initial", "{inbox}/broken_bad_csv.csv"],
     "broken_bad_csv.csv, row 1, column 'line number': not a TLE element line"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--steps", "ingest,refine", "--refine-initial", "{tmp}/none.json"],
     "none.json, column 'refine.initial': file not found"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--steps", "refine", "--refine-initial", "{inbox}/../stale.json",
      "--refine-eop", "{tmp}/finals.txt", "--refine-dut1", "0.1"], "give either an EOP file or UT1-UTC, not both"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--steps", "smooth,ingest"], "steps out of order"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--steps", "ingest,estimate"], "the estimate step needs an initial state"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--stations", "{tmp}/none.csv"], "none.csv, column 'ingest.stations': file"),
    (["-i", "{inbox}", "-o", "{tmp}/out", "--scheduler", "localhost"], "invalid scheduler address"),
])
def test_usage_errors_exit_2_before_any_work(passes, tmp_path, run_cli, args, message):
    args = [a.format(inbox=passes / "inbox", tmp=tmp_path) for a in args]
    run = run_cli(["batch", *args])
    assert run.exit_code == 2, run.stderr
    assert message in run.stderr
    assert not (tmp_path / "out" / "summary.json").exists()


def test_every_setting_is_a_flag_and_documented(run_cli, monkeypatch):
    monkeypatch.setenv("COLUMNS", "250")
    help_text = run_cli(["batch", "--help"]).stdout
    doc = (ROOT / "docs" / "batch.md").read_text()
    for opt in SCHEMA:
        assert opt.flag in help_text, opt.flag
        assert opt.env in doc and f"`{opt.name}`" in doc, opt.name


# ----------------------------------------------------------------------------- inputs, failures, progress

def test_result_names_mirror_sub_directories_and_clashes_are_usage_errors(passes, tmp_path, run_cli):
    inbox = tmp_path / "inbox"
    for station in ("CPH", "KIR"):
        (inbox / station).mkdir(parents=True)
        shutil.copy(next((passes / "inbox").glob(f"{station}-*.csv")), inbox / station / "today.csv")
    shutil.copy(passes / "stations.csv", inbox / "stations.csv")  # the stations file is not an input
    config = write_config(tmp_path / "b.toml", passes, tmp_path / "out",
                          batch={"inputs": [str(inbox / "**" / "*.csv")]},
                          ingest={"stations": str(inbox / "stations.csv")})
    run = run_cli(["batch", config])
    assert run.exit_code == 0, run.stderr
    assert sorted(by_name(tmp_path / "out")) == ["CPH/today", "KIR/today"]
    assert (tmp_path / "out" / "passes" / "KIR" / "today.parquet").exists()
    shutil.copy(inbox / "KIR" / "today.csv", inbox / "KIR" / "today.parquet")
    run = run_cli(["batch", config, "-i", str(inbox / "**" / "today.*")])
    assert run.exit_code == 2 and "two inputs would give the same result name" in run.stderr


def test_an_unexpected_error_is_reported_and_retried_next_run(passes, tmp_path, run_cli, monkeypatch):
    calls = []

    def flaky(ctx, opt):
        calls.append(ctx.name)
        if ctx.name.startswith("CPH") and len(calls) < 10:
            raise RuntimeError("disk on fire")
        return batch_module.smooth_step(ctx, opt)

    monkeypatch.setitem(batch_module.STEPS, "smooth", batch_module.Step("smooth", "input", flaky))
    out = tmp_path / "out"
    config = write_config(tmp_path / "b.toml", passes, out, batch={"inputs": [str(passes / "inbox" / "[CH]*.csv")]})
    run = run_cli(["batch", config, "--workers", "1"])
    cph = [n for n in by_name(out) if n.startswith("CPH")]
    assert run.exit_code == 3 and cph
    for name in cph:
        record = by_name(out)[name]
        assert record["error"] == "internal error: RuntimeError: disk on fire"
        assert record["error_type"] == "internal"
        assert not (out / "passes" / f"{name}.batch.json").exists()  # not recorded: retried next run
    calls.extend(["x"] * 10)
    run = run_cli(["batch", config, "--workers", "1"])
    assert run.exit_code == 0 and f"{len(cph)} to do" in run.stderr


def test_recorded_failures_are_retried_on_request(passes, tmp_path, run_cli):
    out = tmp_path / "out"
    config = write_config(tmp_path / "b.toml", passes, out,
                          batch={"inputs": [str(passes / "inbox" / "broken_*"), str(passes / "inbox" / "MAD*")]})
    assert run_cli(["batch", config]).exit_code == 3
    run = run_cli(["batch", config, "--retry-failed"])
    assert run.exit_code == 3 and "5 to do" in run.stderr
    only_broken = run_cli(["batch", config, "-i", str(passes / "inbox" / "broken_*")])
    assert only_broken.exit_code == 1  # all failed
    assert "0 input(s) ok, 5 failed" in only_broken.stderr


def test_progress_bar_only_on_a_terminal(passes, tmp_path, run_cli):
    import pty

    config = write_config(tmp_path / "b.toml", passes, tmp_path / "out",
                          batch={"inputs": [str(passes / "inbox" / "SVB*.csv")]})
    piped = run_cli(["batch", config, "-o", tmp_path / "piped"])
    assert piped.exit_code == 0 and "\r" not in piped.stderr
    master, slave = pty.openpty()
    exe = Path(sys.executable).with_name("trackproc")
    proc = subprocess.Popen([str(exe), "batch", str(config), "--log", str(tmp_path / "batch.log")],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=slave)
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        seen += chunk
    proc.wait(timeout=60)
    os.close(master)
    assert proc.returncode == 0
    text = seen.decode()
    n = len(list((passes / "inbox").glob("SVB*.csv")))
    assert f"\r[" in text and f"{n}/{n} inputs, 0 failed" in text
    assert "ok (" in (tmp_path / "batch.log").read_text()  # the log went to the file, not the terminal
    assert "ok (" not in text


# ----------------------------------------------------------------------------- the estimate step

def test_estimate_windows_non_convergence_reported_then_redone_alone(passes, tmp_path, run_cli):
    out = tmp_path / "out"
    config = write_config(
        tmp_path / "b.toml", passes, out, batch={"inputs": [str(passes / "inbox" / "[CKS]*.csv"),
                                                            str(passes / "inbox" / "broken_too_few_points.csv")],
                                                 "steps": ["ingest", "smooth", "estimate"]},
        estimate={"initial": str(passes / "stale.json"), "window_s": 43200, "doppler_bias": "offset+drift",
                  "doppler_bias_per": "station", "max_iterations": 1})
    run = run_cli(["batch", config, "--workers", "2"])
    assert run.exit_code == 3, run.stderr
    windows = {w["name"]: w for w in summary(out)["estimates"]}
    assert sorted(windows) == ["2026-03-20T000000Z", "2026-03-20T120000Z", "2026-03-21T000000Z"]
    for window in windows.values():
        assert window["status"] == "failed" and "did not converge in 1 iterations" in window["error"]
        assert window["error_type"] == "processing"
    assert "estimate 2026-03-20T000000Z: failed: did not converge" in run.stderr
    inputs_before = mtimes(out)
    # more iterations: only the windows are redone (the per-pass results do not depend on them)
    run = run_cli(["batch", config, "--workers", "2", "--max-iterations", "20"])
    assert run.exit_code == 3  # the broken input is still failed
    assert "0 to do" in run.stderr and "3 estimate window(s): 0 up to date, 3 to do" in run.stderr
    assert mtimes(out) == inputs_before
    windows = {w["name"]: w for w in summary(out)["estimates"]}
    total = 0
    for name, window in windows.items():
        assert window["status"] == "ok", window["error"]
        n = window["numbers"]
        assert n["converged"] is True and n["iterations"] <= 10 and 0.5 < n["wrms"] < 1.5
        assert n["sigma_along_m"] < 1000
        total += n["inputs"]
        state = json.loads((out / "estimates" / f"{name}.json").read_text())
        assert state["frame"] == "GCRF" and len(state["covariance"]) == len(state["parameters"])
        assert (out / "estimates" / f"{name}.residuals.parquet").exists()
    assert total == sum(1 for r in by_name(out).values() if r["status"] == "ok")
    rows = [line for line in (out / "summary.csv").read_text().splitlines() if line.startswith("estimate,")]
    assert len(rows) == 3 and all(",ok,false," in row and ",true," in row for row in rows)
    run = run_cli(["batch", config, "--workers", "2", "--max-iterations", "20"])
    assert "3 estimate window(s): 3 up to date, 0 to do" in run.stderr


# ----------------------------------------------------------------------------- the refine step

#: Stations for which the truth state of sample_data/truth.json (seed 004 Table 1) is the
#: traverse point of a pass (trackproc.pipeline.refine.traverse_station: km to the left (+) or
#: right (-) of the ground track; highest elevations 34-78 deg), as tests/cli/test_refine_cli.py's TRV.
TRAVERSE_STATIONS = ("station,lat_deg,lon_deg,height_m\n"
                     "TRV,56.454155,9.725833,0\n"     # +500 km
                     "TRF,56.607825,4.914447,0\n"     # +800 km
                     "TRR,55.143123,22.251255,0\n"    # -300 km
                     "TRE,54.190283,27.382994,0\n"    # -650 km
                     "TRN,56.038446,15.300490,0\n"    # +150 km
                     "TRW,56.607022,1.725211,0\n")    # +1000 km
REFINED = ("TRE", "TRF", "TRR", "TRV", "multi")
REFINED_PASSES = ("TRE/TRE-001", "TRF/TRF-001", "TRR/TRR-001", "TRV/TRV-001", "TRN/TRN-001")  # multi: its longest


@pytest.fixture(scope="session")
def refine_passes(tmp_path_factory) -> Path:
    """``inbox/``: one-way Doppler passes (5 s, 0.2 Hz, a 150 Hz transmitter offset) around the
    traverse epoch 2026-03-20T09:30:00Z of the Table 1 truth, one wide CSV per station (TRE,
    TRF, TRR, TRV); ``multi``: TRN's whole pass and the first 40 samples of TRW's; ``short``:
    7 samples of TRE's pass (smoothed, but too few to refine). ``stations.csv``, ``stale.json``."""
    import numpy as np
    import pandas as pd

    from trackproc.io.stations import parse_stations
    from trackproc.io.statefile import read_state
    from trackproc.pipeline.simulate import SimulateOptions, simulate

    root = tmp_path_factory.mktemp("refine_batch")
    inbox = root / "inbox"
    inbox.mkdir()
    (root / "stations.csv").write_text(TRAVERSE_STATIONS)
    shutil.copy(ROOT / "sample_data" / "stale.json", root / "stale.json")
    sim = simulate(read_state(str(ROOT / "sample_data" / "truth.json")),
                   parse_stations(TRAVERSE_STATIONS.encode(), "st"),
                   SimulateOptions(duration_s=1800, step_s=5, start=np.datetime64("2026-03-20T09:15:00"),
                                   kinds=("doppler",), sigma_doppler_hz=0.2, freq_offset_hz=150.0, seed=4))
    wide = sim.wide()
    wide = wide.assign(time=wide["time"].dt.strftime("%Y-%m-%dT%H:%M:%SZ"))
    rows = {station: group for station, group in wide.groupby("station")}
    assert all(len(rows[s]) > 100 for s in rows)  # one pass each, ~10 minutes
    for station in ("TRE", "TRF", "TRR", "TRV"):
        rows[station].to_csv(inbox / f"{station}.csv", index=False)
    pd.concat([rows["TRW"].head(40), rows["TRN"]]).to_csv(inbox / "multi.csv", index=False)
    middle = len(rows["TRE"]) // 2
    rows["TRE"].iloc[middle - 3:middle + 4].to_csv(inbox / "short.csv", index=False)
    return root


def refine_config(path: Path, root: Path, output: Path, **sections) -> Path:
    """``write_config`` for ``refine_passes``: ingest -> smooth -> refine from the stale state
    (UT1-UTC = 0 given: no EOP warning on every input)."""
    refine = {"initial": str(root / "stale.json"), "dut1": 0.0, **sections.pop("refine", {})}
    batch = {"inputs": [str(root / "inbox")], "steps": ["ingest", "smooth", "refine"], **sections.pop("batch", {})}
    ingest = {"stations": str(root / "stations.csv"), **sections.pop("ingest", {})}
    return write_config(path, root, output, batch=batch, ingest=ingest, refine=refine, **sections)


@pytest.mark.slow
@pytest.mark.subprocess
def test_refine_chain_on_dask_threads_gives_the_serial_bytes(refine_passes, tmp_path, run_cli):
    """A refine chain runs its tasks with the compiled kernels (as TRACKPROC_JIT=1, a per-thread
    default): on a Dask cluster whose workers run two tasks at a time in threads, the refined
    states are the serial run's, byte for byte."""
    distributed = pytest.importorskip("distributed")
    serial, dask = tmp_path / "serial", tmp_path / "dask"
    config = refine_config(tmp_path / "r.toml", refine_passes, tmp_path / "unused")
    assert run_cli(["batch", config, "-o", serial, "--workers", "1"]).exit_code == 3
    with distributed.LocalCluster(n_workers=2, threads_per_worker=2, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        run = run_cli(["batch", config, "-o", dask, "--scheduler", cluster.scheduler_address])
    assert run.exit_code == 3, run.stderr
    reference = digest(serial)
    assert sum(name.endswith(".refined.json") for name in reference) == 5
    assert digest(dask) == reference


def test_refine_step_writes_refined_states_and_fails_only_the_pass_it_cannot_refine(refine_passes, tmp_path,
                                                                                    run_cli):
    import numpy as np

    from trackproc.io.statefile import read_state

    out = tmp_path / "out"
    config = refine_config(tmp_path / "r.toml", refine_passes, out)
    run = run_cli(["batch", config, "--workers", "2"])
    assert run.exit_code == 3, run.stderr
    assert "Traceback" not in run.stderr
    records = by_name(out)
    assert sorted(records) == sorted(REFINED + ("short",))
    # the pass too short to refine fails alone, with its reason, and leaves no results
    short = records["short"]
    assert short["status"] == "failed" and short["error_type"] == "processing"
    assert short["error"] == "refine TRE/TRE-001: too few samples in the pass: 7 (at least 8 are needed)"
    assert "short: failed: refine TRE/TRE-001: too few samples" in run.stderr
    assert [p.name for p in (out / "passes").glob("short.*")] == ["short.batch.json"]
    # the others: a refined state file and the key numbers
    truth = read_state(str(ROOT / "sample_data" / "truth.json"))
    prior_sigma = np.array(json.loads((refine_passes / "stale.json").read_text())["sigma"][:6])   # 10 km, 5 m/s
    for name in REFINED:
        record = records[name]
        assert record["status"] == "ok", record["error"]
        n = record["numbers"]
        assert n["converged"] is True and 1 <= n["iterations"] <= 10
        assert n["traverse_utc"][:19] in ("2026-03-20T09:29:59", "2026-03-20T09:30:00")  # the truth's traverse
        # a refined state replaces the stale one only when it predicts better with probability >= 0.9
        # (methods/estimation/decision.py); a weak pass keeps the stale state and its covariance
        assert n["decision"] in ("replaced", "kept"), n
        if n["decision"] == "replaced":
            assert 0.1 < n["residual_rms"] < 0.3 and n["residual_rms_unit"] == "Hz"
        assert all(0 < n[k] < 2e4 for k in ("sigma_radial_m", "sigma_along_m", "sigma_cross_m"))
        assert "passes/" + name + ".refined.json" in record["outputs"]
        doc = json.loads((out / "passes" / f"{name}.refined.json").read_text())
        assert doc["epoch"] == n["traverse_utc"] and doc["parameters"][-1].startswith("doppler_offset:")
        stale = doc["at_stale_epoch"]  # the refined orbit at the stale epoch holds the truth within 3 sigma
        err = np.r_[stale["position_m"], stale["velocity_m_s"]] - truth.rv
        assert np.all(np.abs(err) < 3 * np.array(stale["sigma"][:6])), name
        # ... with a sigma the pass supports: the stale covariance is refine's a-priori, and data only add
        # information (a posterior is never wider than its prior): each sigma at most the a-priori's
        assert np.all(np.array(stale["sigma"][:6]) <= prior_sigma * (1 + 1e-9)), (name, stale["sigma"][:6])
        assert record["details"]["refine"]["traverse"]["epoch"] == n["traverse_utc"]
    assert [records[n]["numbers"]["refined_pass"] for n in REFINED] == list(REFINED_PASSES)
    # an input of two passes: the one with the most samples is refined, and the summary says so
    multi = records["multi"]
    assert multi["numbers"]["passes"] == 2
    candidates = multi["details"]["refine"]["candidates"]
    assert [(c["pass_id"], c["samples"]) for c in candidates][1] == ("TRW-001", 40)
    assert candidates[0]["pass_id"] == "TRN-001" and candidates[0]["samples"] > 100
    assert any(w.startswith("2 passes in the input: refined TRN/TRN-001") and "not refined: TRW/TRW-001 (40)" in w
               for w in multi["warnings"])
    # the batch's refinement is trackproc refine's on the stored pass file, byte for byte: batch
    # runs its tasks as TRACKPROC_JIT=1 does (the compiled kernels when numba is installed)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TRACKPROC_JIT", "1")
        cli = run_cli(["-q", "refine", out / "passes" / "multi.parquet", "--initial", refine_passes / "stale.json",
                       "--pass-id", "TRN-001", "--dut1", "0", "-o", tmp_path / "cli.json"])
    assert cli.exit_code == 0, cli.stderr
    assert (tmp_path / "cli.json").read_bytes() == (out / "passes" / "multi.refined.json").read_bytes()
    # summary.csv: the refine columns
    header, *lines = (out / "summary.csv").read_text().splitlines()
    columns = header.split(",")
    assert {"refined_pass", "traverse_utc", "converged", "iterations", "residual_rms", "sigma_radial_m"} <= set(columns)
    row = dict(zip(columns, next(line for line in lines if line.startswith("pass,TRV,")).split(",")))
    assert row["refined_pass"] == "TRV/TRV-001" and row["converged"] == "true" and row["residual_rms_unit"] == "Hz"
    # a re-run skips everything, the recorded failure too
    before = mtimes(out)
    run = run_cli(["batch", config])
    assert run.exit_code == 3 and "6 input(s): 6 up to date, 0 to do" in run.stderr
    assert mtimes(out) == before


def test_changing_a_refine_setting_redoes_only_the_refinements(refine_passes, tmp_path, run_cli, monkeypatch):
    out = tmp_path / "out"
    config = refine_config(tmp_path / "r.toml", refine_passes, out,
                           batch={"steps": ["ingest", "smooth", "refine", "estimate"]},
                           estimate={"initial": str(refine_passes / "stale.json"), "dut1": 0.0,
                                     "doppler_bias": "offset"})
    first = run_cli(["batch", config])
    assert first.exit_code == 3, first.stderr
    records = by_name(out)
    (window,) = summary(out)["estimates"]
    assert window["status"] == "ok" and window["members"] == list(REFINED)  # not the input refine failed
    refined = {n: (out / "passes" / f"{n}.refined.json").read_bytes() for n in REFINED}

    def table_outputs():
        return {p: t for p, t in mtimes(out).items() if not p.endswith((".refined.json", ".batch.json"))}

    tables, estimate = table_outputs(), (out / "estimates" / "all.json").stat().st_mtime_ns
    # a [refine] setting (here through the environment): only the refinements are redone, from
    # the stored pass tables; the tables, the smoothing and the window's estimate stay as they are
    monkeypatch.setenv("TRACKPROC_BATCH_REFINE_OUTPUT_EPOCH", "stale")
    run = run_cli(["batch", config])
    assert run.exit_code == 3, run.stderr
    assert ("6 input(s): 0 up to date, 6 to do (steps ingest -> smooth -> refine -> estimate; 5 of them refine "
            "only, from their stored ingest and smooth results)") in run.stderr
    assert "1 estimate window(s): 1 up to date, 0 to do" in run.stderr
    assert table_outputs() == tables and (out / "estimates" / "all.json").stat().st_mtime_ns == estimate
    for name in REFINED:
        assert json.loads((out / "passes" / f"{name}.refined.json").read_text())["epoch"] == "2026-03-20T09:30:00.000Z"
    # back to the default: the same bytes and records as the first run made from the raw inputs
    monkeypatch.delenv("TRACKPROC_BATCH_REFINE_OUTPUT_EPOCH")
    run = run_cli(["batch", config])
    assert run.exit_code == 3 and "5 of them refine only" in run.stderr
    assert {n: (out / "passes" / f"{n}.refined.json").read_bytes() for n in REFINED} == refined
    assert {n: comparable(r) for n, r in by_name(out).items()} == {n: comparable(r) for n, r in records.items()}
    assert table_outputs() == tables
    # one iteration is not enough: every refinement fails with its reason (exit 1: none left)
    run = run_cli(["batch", config, "--refine-max-iterations", "1"])
    assert run.exit_code == 1, run.stderr
    for name, record in by_name(out).items():
        assert record["status"] == "failed" and record["error_type"] == "processing"
        if name != "short":
            assert record["error"].startswith(f"refine {dict(zip(REFINED, REFINED_PASSES))[name]}: did not "
                                              "converge in 1 iterations"), record["error"]
            assert not (out / "passes" / f"{name}.parquet").exists()


# ----------------------------------------------------------------------------- the nightly recipe

def test_nightly_recipe(passes, tmp_path):
    header = (ROOT / "cli" / "nightly.sh").read_text().splitlines()[:12]
    cron = [line for line in header if "nightly.sh" in line and line.lstrip("# ").split()[0].isdigit()]
    assert cron, "the header holds a crontab line"
    out, logs = tmp_path / "out", tmp_path / "logs"
    config = write_config(tmp_path / "nightly.toml", passes, out,
                          batch={"inputs": [str(passes / "inbox" / "MAD*.csv"),
                                            str(passes / "inbox" / "broken_bad_csv.csv")]})
    env = dict(os.environ, TRACKPROC=str(Path(sys.executable).with_name("trackproc")))
    cmd = ["bash", str(ROOT / "cli" / "nightly.sh"), str(config), str(logs)]
    first = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert first.returncode == 3, first.stderr
    assert "partial failure (exit 3)" in first.stderr and first.stderr.count("\n") == 1
    (log,) = logs.glob("batch-*.log")
    text = log.read_text()
    assert "broken_bad_csv: failed: " in text and "row 2, column 'time'" in text
    assert "summary.csv" in first.stderr
    good = [n for n, r in by_name(out).items() if r["status"] == "ok"]
    assert len(good) == len(list((passes / "inbox").glob("MAD*.csv")))
    config.write_text(config.read_text().replace(', "' + str(passes / "inbox" / "broken_bad_csv.csv") + '"', ""))
    second = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert second.returncode == 0 and second.stderr == ""  # silent: cron mails nothing
    assert f"{len(good)} up to date, 0 to do" in log.read_text()


# ----------------------------------------------------------------------------- a worker that dies

class _Crash:
    """Unpickling this in a worker process kills it, as an out-of-memory kill or a segfault would."""

    def __reduce__(self):
        return (os._exit, (70,))


def test_a_dying_worker_fails_only_its_own_input(passes):
    from trackproc.pipeline.batch.config import resolve

    settings = resolve(None, {"ingest.stations": str(passes / "stations.csv"), "ingest.carrier_hz": 2.2e9,
                              "ingest.mode": "one-way"}, environ={})
    options = {s: settings.section(s) for s in ("ingest", "smooth")}
    stations = (passes / "stations.csv").read_bytes()
    paths = sorted((passes / "inbox").glob("HBK*.csv")) + sorted((passes / "inbox").glob("MAD*.csv"))

    def task(path, crash=False):
        return batch_module.Task(kind="input", name=path.stem + ("-crash" if crash else ""), key="k",
                                 steps=("ingest", "smooth"),
                                 options={**options, "smooth": _Crash()} if crash else options,
                                 files={"ingest.stations": stations}, paths={"ingest.stations": "stations.csv"},
                                 source=str(path), data=path.read_bytes())

    tasks = [task(p) for p in paths]
    tasks.insert(1, task(paths[0], crash=True))
    results = {}
    executor = batch_module.PoolExecutor(2)
    try:
        batch_module.execute(executor, tasks, lambda t: t, lambda t, r: results.__setitem__(t.name, r))
    finally:
        executor.close()
    assert sorted(results) == sorted(t.name for t in tasks)
    crashed = results.pop(f"{paths[0].stem}-crash")
    assert crashed.status == "failed" and crashed.error_type == "internal" and "BrokenProcessPool" in crashed.error
    assert all(r.status == "ok" for r in results.values()), {n: r.error for n, r in results.items()}
