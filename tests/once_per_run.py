"""A module fixture's result built once per test run, also under pytest-xdist.

Each xdist worker builds module-scoped fixtures of its own: the Orekit comparisons
(tests/cli/test_against_orekit.py, tests/io/test_forces_orekit.py) ran their Java child and the
trackproc side twice when their tests landed on both workers. ``--dist loadgroup`` would keep them
on one worker, but with pytest 9.2 and pytest-xdist 3.8 its groups are silently dropped
(pytest-xdist issue 1386: the group suffix is written to a node id field pytest no longer reads),
so the result is shared through the run's common temporary directory instead, the first worker
building it under a file lock (the recipe of pytest-xdist's documentation,
"Making session-scoped fixtures execute only once", with ``fcntl`` in place of ``filelock``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable

#: keys of a result that hold paths (written as text, read back as Path)
_PATH_KEYS = ("dir", "eop")


def once_per_run(tmp_path_factory, name: str, build: Callable[[Path], dict]) -> dict:
    """``build(directory)`` -> a JSON-able dict (Path values under ``dir``/``eop`` allowed), run in
    ``directory`` by the first worker of this run that asks; the others wait and read its result."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        return build(tmp_path_factory.mktemp(name))           # one process: nothing to share
    import fcntl

    root = tmp_path_factory.getbasetemp().parent              # common to this run's workers only
    directory, done = root / name, root / f"{name}.json"
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            directory.mkdir(exist_ok=True)
            result = build(directory)
            stored = {k: str(v) if k in _PATH_KEYS else v for k, v in result.items()}
            tmp = done.with_suffix(".tmp")
            tmp.write_text(json.dumps(stored))
            tmp.replace(done)
            return result
    stored = json.loads(done.read_text())
    return {k: Path(v) if k in _PATH_KEYS else v for k, v in stored.items()}
