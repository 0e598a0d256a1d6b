"""The parsed-table cache (io/table_cache.py): EOP and ICGEM tables read from the cache are the
parser's own arrays bit for bit; a corrupt or foreign entry is parsed again and rewritten;
processes filling the same entry at once all get the parser's result and leave one whole entry."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from trackproc.io import eop, icgem, table_cache

astropy_iers_data = pytest.importorskip("astropy_iers_data")
FINALS = Path(astropy_iers_data.IERS_A_FILE)
DATE = np.datetime64("2026-03-20T06:00:00", "s")


def _forget():
    """Drop this process's memory of parsed tables: the next read goes to the disk cache."""
    table_cache._MEMO.clear()
    eop._PARSED.clear()


def _eop_arrays(table):
    return [table.mjd, table.ut1_minus_tai_s, table.xp_rad, table.yp_rad]


def _entries(folder: Path, kind: str):
    return sorted(folder.glob(f"{kind}-*.npz"))


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv(table_cache.CACHE_ENV, str(folder))
    _forget()
    yield folder
    _forget()


def test_cache_location_and_switch(monkeypatch, tmp_path):
    monkeypatch.delenv(table_cache.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert table_cache.cache_dir() == str(tmp_path / "trackproc")
    assert table_cache.cache_dir("help") == str(tmp_path / "trackproc" / "help")
    monkeypatch.setenv(table_cache.CACHE_ENV, str(tmp_path / "elsewhere"))
    assert table_cache.cache_dir() == str(tmp_path / "elsewhere")
    for off in ("", "0", "off", "OFF"):
        monkeypatch.setenv(table_cache.CACHE_ENV, off)
        assert table_cache.cache_dir() is None and table_cache.cache_dir("help") is None


def test_eop_from_the_cache_is_the_parse(cache, monkeypatch):
    monkeypatch.setenv(table_cache.CACHE_ENV, "off")
    plain = eop.read_finals2000a(FINALS)
    assert not cache.exists()                                   # off: nothing written
    monkeypatch.setenv(table_cache.CACHE_ENV, str(cache))
    _forget()
    first = eop.read_finals2000a(FINALS)                        # parsed, entry written
    (entry,) = _entries(cache, "finals2000a")
    _forget()
    calls = []
    monkeypatch.setattr(eop, "_parse_rows", lambda path: calls.append(path))
    cached = eop.read_finals2000a(FINALS)                       # from the entry: the parser is not called
    assert calls == []
    for a, b, c in zip(_eop_arrays(plain), _eop_arrays(first), _eop_arrays(cached)):
        assert a.dtype == c.dtype and np.array_equal(a, b) and np.array_equal(a, c)
    assert cached.source == plain.source and entry.stat().st_size > 0


def test_icgem_from_the_cache_is_the_parse(cache, monkeypatch):
    path = icgem.default_field_path()
    cases = [(20, None, DATE), (8, 4, None), (None, None, "2010-01-01T00:00:00")]
    monkeypatch.setenv(table_cache.CACHE_ENV, "off")
    plain = [icgem.read_icgem(path, *case) for case in cases]
    monkeypatch.setenv(table_cache.CACHE_ENV, str(cache))
    _forget()
    icgem.read_icgem(path, 2)                                   # fills the cache (whole file)
    assert len(_entries(cache, "icgem")) == 1
    _forget()
    monkeypatch.setattr(icgem, "_parse", lambda *a: pytest.fail("parsed again"))
    for case, want in zip(cases, plain):
        got = icgem.read_icgem(path, *case)
        assert got.cbar.shape == want.cbar.shape
        assert np.array_equal(got.cbar, want.cbar) and np.array_equal(got.sbar, want.sbar), case
        assert (got.gm_m3_s2, got.radius_m, got.name, got.tide_system, got.epoch) == \
               (want.gm_m3_s2, want.radius_m, want.name, want.tide_system, want.epoch)
    with pytest.raises(Exception, match="degree 71 requested"):
        icgem.read_icgem(path, 71)                              # the file's max_degree is checked as before


def test_a_changed_source_is_a_new_entry(cache, tmp_path):
    copy = tmp_path / "finals.data"
    lines = FINALS.read_text().splitlines(keepends=True)[:400]
    copy.write_text("".join(lines))
    before = eop.read_finals2000a(copy)
    _forget()
    copy.write_text("".join(lines[:300]))                        # same name, other content
    after = eop.read_finals2000a(copy)
    assert len(_entries(cache, "finals2000a")) == 2 and len(after.mjd) < len(before.mjd)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "foreign"])
def test_a_corrupt_entry_is_parsed_again_and_rewritten(cache, damage):
    want = _eop_arrays(eop.read_finals2000a(FINALS))
    (entry,) = _entries(cache, "finals2000a")
    good = entry.read_bytes()
    if damage == "garbage":
        entry.write_bytes(b"not a zip file at all")
    elif damage == "truncated":
        entry.write_bytes(good[: len(good) // 2])
    else:                                   # a whole npz, but of another key: never taken for this file
        np.savez(entry, _key=np.array("finals2000a:0"), mjd=np.zeros(3), dut1=np.zeros(3), xp=np.zeros(3),
                 yp=np.zeros(3))
    _forget()
    got = _eop_arrays(eop.read_finals2000a(FINALS))
    assert all(np.array_equal(a, b) for a, b in zip(want, got))
    assert entry.read_bytes() == good                           # rewritten whole
    assert not list(cache.glob(".*tmp"))


def test_an_unwritable_cache_only_costs_the_parse(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache directory should be")
    monkeypatch.setenv(table_cache.CACHE_ENV, str(blocker / "cache"))
    _forget()
    monkeypatch.setenv(table_cache.CACHE_ENV, "off")
    want = _eop_arrays(eop.read_finals2000a(FINALS))
    _forget()
    monkeypatch.setenv(table_cache.CACHE_ENV, str(blocker / "cache"))
    got = _eop_arrays(eop.read_finals2000a(FINALS))
    assert all(np.array_equal(a, b) for a, b in zip(want, got))
    _forget()


@pytest.mark.subprocess
def test_concurrent_writers_leave_one_whole_entry(cache):
    """Four processes miss the same entry together and all write it: each gets the parser's
    arrays, one whole entry is left and no temporary file."""
    probe = ("import sys, hashlib, numpy as np; from trackproc.io import icgem; "
             "f = icgem.read_icgem(icgem.default_field_path(), 30, None, np.datetime64('2026-03-20T06:00:00', 's')); "
             "print(hashlib.sha256(f.cbar.tobytes() + f.sbar.tobytes()).hexdigest())")
    env = {**__import__("os").environ, table_cache.CACHE_ENV: str(cache)}
    procs = [subprocess.Popen([sys.executable, "-c", probe], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, env=env) for _ in range(4)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-500:] for o in outs]
    env[table_cache.CACHE_ENV] = "off"
    plain = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True)
    assert {o[0].strip() for o in outs} == {plain.stdout.strip()}
    (entry,) = _entries(cache, "icgem")
    assert not list(cache.glob(".*tmp"))
    with np.load(entry, allow_pickle=False) as z:               # whole and readable
        assert str(z["_key"]).startswith("icgem:") and z["static_nm"].shape[1] == 2
