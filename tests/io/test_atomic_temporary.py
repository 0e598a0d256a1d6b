"""io/atomic.py ``open_atomic``: the temporary file it writes first (its name, mode and directory)
and all-or-none on an interrupted write; the references are a file made with plain ``open`` (mode
under the same umask) and the directory listing itself."""

from __future__ import annotations

import os

import pytest

from trackproc.errors import OutputError
from trackproc.io import atomic
from trackproc.io.atomic import open_atomic, write_bytes


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.json"
    target.write_bytes(b"old")
    seen = []
    with pytest.raises(RuntimeError):
        with open_atomic(target) as handle:
            handle.write(b"half of the new")
            seen = sorted(p.name for p in tmp_path.iterdir())
            raise RuntimeError("killed mid-write")
    # while it was written: the target as it was, and one temporary the leftover sweep would find
    # (pipeline/batch/store.py remove_leftovers: ".*.tmp")
    assert len(seen) == 2 and seen[1] == "out.json"
    assert seen[0].startswith(".out.json.") and seen[0].endswith(".tmp")
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]
    assert target.read_bytes() == b"old"


def test_the_file_has_the_mode_a_plain_open_gives(tmp_path):
    mask = os.umask(0o027)
    try:
        write_bytes(tmp_path / "a.bin", b"x")
        with open(tmp_path / "plain.bin", "wb") as handle:
            handle.write(b"x")
    finally:
        os.umask(mask)
    assert (tmp_path / "a.bin").stat().st_mode & 0o777 == (tmp_path / "plain.bin").stat().st_mode & 0o777 == 0o640


def test_missing_directories_are_made_and_a_file_in_the_way_is_an_output_error(tmp_path):
    write_bytes(tmp_path / "new" / "deeper" / "a.bin", b"abc")
    assert (tmp_path / "new" / "deeper" / "a.bin").read_bytes() == b"abc"
    (tmp_path / "file").write_bytes(b"")
    for path in (tmp_path / "file" / "a.bin", tmp_path / "file" / "sub" / "a.bin"):
        with pytest.raises(OutputError, match="not a directory"):
            write_bytes(path, b"abc")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "new"]


def test_a_taken_temporary_name_is_skipped(tmp_path, monkeypatch):
    draws = iter([b"\x01" * 6, b"\x01" * 6, b"\x02" * 6])
    monkeypatch.setattr(atomic.os, "urandom", lambda n: next(draws))
    (tmp_path / f".a.bin.{'01' * 6}.tmp").write_bytes(b"someone else's")
    write_bytes(tmp_path / "a.bin", b"mine")
    assert (tmp_path / "a.bin").read_bytes() == b"mine"
    assert (tmp_path / f".a.bin.{'01' * 6}.tmp").read_bytes() == b"someone else's"


def _calls(monkeypatch):
    """The order of the file-system calls write_bytes makes (recorded, then done)."""
    seen = []
    for name in ("write", "fsync", "close", "replace", "unlink"):
        real = getattr(os, name)
        monkeypatch.setattr(atomic.os, name, lambda *a, _real=real, _name=name: (seen.append(_name), _real(*a))[1])
    return seen


def test_write_bytes_syncs_before_the_rename_and_replaces_the_old_file(tmp_path, monkeypatch):
    """The durable contract of the module docstring: the data fsynced, then renamed over the
    target (which keeps its old content until then); the reference is the file read back."""
    target = tmp_path / "out.bin"
    target.write_bytes(b"old content")
    seen = _calls(monkeypatch)
    data = bytes(range(256)) * 300
    write_bytes(target, data)
    assert seen == ["write", "fsync", "close", "replace"]
    assert target.read_bytes() == data
    assert [p.name for p in tmp_path.iterdir()] == ["out.bin"]


def test_write_bytes_failing_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "out.bin"
    target.write_bytes(b"old")

    def full(fd, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.os, "write", full)
    with pytest.raises(OutputError, match="out.bin"):
        write_bytes(target, b"new")
    assert [p.name for p in tmp_path.iterdir()] == ["out.bin"] and target.read_bytes() == b"old"


def test_write_bytes_in_a_transaction_is_held_until_it_ends(tmp_path):
    """all_or_none: the written file appears at the end of the block, or never."""
    with atomic.all_or_none():
        write_bytes(tmp_path / "a.bin", b"a")
        assert not (tmp_path / "a.bin").exists()
    assert (tmp_path / "a.bin").read_bytes() == b"a"
    with pytest.raises(RuntimeError):
        with atomic.all_or_none():
            write_bytes(tmp_path / "b.bin", b"b")
            raise RuntimeError("the second output failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin"]


def test_write_bytes_to_a_device_or_a_directory(tmp_path):
    write_bytes(os.devnull, b"discarded")                     # written through, not renamed over
    assert os.path.exists(os.devnull) and not os.path.isfile(os.devnull)
    with pytest.raises(OutputError, match="directory"):
        write_bytes(tmp_path, b"x")
