"""Hostile class: SIGTERM/SIGINT of a single command removes its temporary files, exits 128 + n with
one line on stderr and leaves no output (issue 14 item 6; batch's pool is tested in test_batch)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from hostile import STATIONS, TRUTH, assert_no_temporaries
from trackproc.cli import guard
from trackproc.errors import Terminated
from trackproc.io.atomic import all_or_none, open_atomic


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_signal_inside_a_write_removes_the_temporary(tmp_path, signum):
    restore = guard.install_signal_handlers()
    target = tmp_path / "out.bin"
    try:
        with pytest.raises(Terminated) as caught:
            with open_atomic(target) as handle:
                handle.write(b"half of it")
                os.kill(os.getpid(), signum)
                time.sleep(1)   # the handler raises here
    finally:
        restore()
    assert caught.value.signum == signum
    assert not target.exists()
    assert_no_temporaries(tmp_path)
    assert guard.describe(caught.value, "simulate")[1] == 128 + signum


def test_signal_between_two_outputs_leaves_neither(tmp_path):
    restore = guard.install_signal_handlers()
    first, second = tmp_path / "first.json", tmp_path / "second.json"
    try:
        with pytest.raises(Terminated):
            with all_or_none():
                with open_atomic(first) as handle:
                    handle.write(b"{}")
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(1)
                with open_atomic(second) as handle:   # never reached
                    handle.write(b"{}")
    finally:
        restore()
    assert not first.exists() and not second.exists()
    assert_no_temporaries(tmp_path)


def test_handlers_are_restored(tmp_path):
    before = signal.getsignal(signal.SIGTERM)
    restore = guard.install_signal_handlers()
    assert signal.getsignal(signal.SIGTERM) is not before
    restore()
    assert signal.getsignal(signal.SIGTERM) is before


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_of_a_running_command(tmp_path, signum):
    out = tmp_path / "long.parquet"
    cmd = [sys.executable, "-m", "trackproc", "-v", "simulate", "--state", str(TRUTH), "--stations", str(STATIONS),
           "--duration", "2000000", "--step", "1", "-o", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stderr.readline()   # "started": the command is running, handlers are in place
        assert "DEBUG" in first and "started" in first, first
        time.sleep(0.5)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signum, err
    lines = [line for line in err.splitlines() if line.strip() and "WARNING" not in line and "DEBUG" not in line]
    assert len(lines) == 1 and lines[0].startswith("trackproc: error: terminated by"), err
    assert "Traceback" not in err
    assert not out.exists()
    assert_no_temporaries(tmp_path)


def test_forked_child_dies_of_the_signal_silently(tmp_path):
    """A worker forked after the handlers were installed (batch's pool) is not turned into a
    Python exception (which would print a traceback): it dies of SIGTERM as before."""
    restore = guard.install_signal_handlers()
    try:
        pid = os.fork()
        if pid == 0:   # the child: wait to be terminated
            time.sleep(30)
            os._exit(0)
        time.sleep(0.2)
        os.kill(pid, signal.SIGTERM)
        _, status = os.waitpid(pid, 0)
    finally:
        restore()
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGTERM
