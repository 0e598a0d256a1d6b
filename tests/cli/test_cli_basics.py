"""The CLI shell: version, help, exit-code table, atomic writes, quiet broken pipes."""

import os
import subprocess
import sys

import pytest

from trackproc import __version__
from trackproc.errors import EXIT_INPUT, EXIT_PROCESSING, InputError, ProcessingError
from trackproc.io.atomic import open_atomic, write_text


def run(*args, **kw):
    return subprocess.run([sys.executable, "-m", "trackproc", *args], capture_output=True, text=True, **kw)


def test_version():
    out = run("--version")
    assert out.returncode == 0
    assert out.stdout.strip() == f"trackproc {__version__}"


def test_help_lists_commands_and_imports_nothing_heavy():
    out = run("--help")
    assert out.returncode == 0
    for name in ("ingest", "info", "simulate"):
        assert name in out.stdout
    probe = subprocess.run(
        [sys.executable, "-c", "import sys, trackproc.cli.app as a; a._register();"
         "print(sorted(m for m in ('numpy','pandas','scipy','pyarrow','erfa') if m in sys.modules))"],
        capture_output=True, text=True, check=True)
    assert probe.stdout.strip() == "[]"


def test_unknown_command_is_usage_error():
    out = run("no-such-command")
    assert out.returncode == 2
    assert "Traceback" not in out.stderr


def test_input_error_message_names_file_row_column():
    err = InputError("not a number", file="pass.csv", row=7, column="range_m", found="abc",
                     expected="a finite float in metres")
    text = str(err)
    assert text.startswith("pass.csv, row 7, column 'range_m': not a number")
    assert "found 'abc'" in text and "expected a finite float in metres" in text
    assert err.exit_code == EXIT_INPUT
    assert ProcessingError("did not converge").exit_code == EXIT_PROCESSING


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.json"
    write_text(target, "old")
    with pytest.raises(RuntimeError):
        with open_atomic(target) as handle:
            handle.write(b"half")
            raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert os.listdir(tmp_path) == ["out.json"]


def test_atomic_write_gives_the_usual_file_mode(tmp_path):
    mask = os.umask(0o022)
    try:
        write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(mask)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


def test_atomic_write_to_a_device_writes_through(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    import threading

    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    reader.start()
    write_text(fifo, "through")
    reader.join(5)
    assert got == [b"through"]
    assert sorted(os.listdir(tmp_path)) == ["fifo"]  # no temp file, the FIFO still a FIFO
    write_text("/dev/null", "x")
    assert os.path.exists("/dev/null") and not os.path.isfile("/dev/null")


def test_reader_closing_the_pipe_early_ends_quietly_with_141(tmp_path):
    """`trackproc ... | head` : no traceback, exit 141 (as a Unix tool killed by SIGPIPE), never 0
    with a silently truncated output."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    cmd = [sys.executable, "-m", "trackproc", "-q", "propagate", os.path.join(root, "sample_data", "truth.json"),
           "--span", "43200", "--step", "1", "--format", "csv", "-o", "-"]
    writer = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    writer.stdout.read(10)
    writer.stdout.close()  # the reader goes away after 10 bytes of several megabytes
    err = writer.stderr.read().decode()
    assert writer.wait(timeout=120) == 141
    assert "Traceback" not in err and err.strip() == ""
