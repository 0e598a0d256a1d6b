"""Shared checks of the hostile-input corpus (issue 14): every rejected case gives the promised
exit code, exactly one line on stderr naming the file/row/field, no traceback, no output file
and no temporary file left behind."""

from __future__ import annotations

import json
from pathlib import Path

SAMPLE = Path(__file__).resolve().parent.parent / "sample_data"
STATIONS = SAMPLE / "stations.csv"
TRUTH = SAMPLE / "truth.json"
DOPPLER_CSV = SAMPLE / "doppler_pass.csv"
MULTI = SAMPLE / "multistation.parquet"
TDM_DIR = Path(__file__).resolve().parent / "data" / "tdm"

TRUTH_DOC = json.loads(TRUTH.read_text())


def state_doc(**changes) -> str:
    doc = {k: v for k, v in TRUTH_DOC.items() if k != "comment"}
    doc.update(changes)
    return json.dumps(doc)


def assert_rejected(result, code: int, *needles: str, outputs=(), folder: Path | None = None) -> str:
    """``result`` (a CliResult) failed as the README promises; returns its one error line."""
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == code, (result.exit_code, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    assert len(lines) == 1, result.stderr
    line = lines[0]
    assert line.startswith("trackproc: error: "), line
    for needle in needles:
        assert needle in line, (needle, line)
    for path in outputs:
        assert not Path(path).exists(), f"{path} was written"
    if folder is not None:
        assert_no_temporaries(folder)
    return line


def assert_no_temporaries(folder: Path) -> None:
    left = [p.name for p in Path(folder).rglob("*.tmp")]
    assert not left, left
