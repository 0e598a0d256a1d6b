"""Shared fixtures: run the ``trackproc`` CLI in-process, write small input files."""

from __future__ import annotations

import logging
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from typer.testing import CliRunner

from trackproc.cli import app as cli_app

cli_app._register()

STATIONS_CSV = "station,lat_deg,lon_deg,height_m\nZHY,40.0,116.0,50\nKIR,67.8,20.9,400\n"


@dataclass
class CliResult:
    exit_code: int
    stdout_bytes: bytes
    stderr: str

    @property
    def stdout(self) -> str:
        return self.stdout_bytes.decode("utf-8")


@pytest.fixture
def run_cli():
    """``run_cli(args, input=bytes)`` -> CliResult: the real entry point (``main``: exit codes and
    one-line errors) inside CliRunner's isolated stdin/stdout/stderr."""
    runner = CliRunner()

    def run(args, input: bytes | str | None = None) -> CliResult:
        root = logging.getLogger()
        handlers, level = list(root.handlers), root.level
        try:
            with runner.isolation(input=input) as (out, err, _):
                code = cli_app.main([str(a) for a in args])
                sys.stdout.flush()
                sys.stderr.flush()
                return CliResult(code, out.getvalue(), err.getvalue().decode("utf-8"))
        finally:
            root.handlers[:] = handlers
            root.setLevel(level)

    return run


@pytest.fixture
def write(tmp_path: Path):
    """``write(name, text_or_bytes)`` -> path of a new file in ``tmp_path``."""

    def make(name: str, content: str | bytes) -> Path:
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content.encode("utf-8") if isinstance(content, str) else content)
        return path

    return make


@pytest.fixture
def stations_csv(write) -> Path:
    """Stations ZHY (40 N, 116 E, 50 m) and KIR (67.8 N, 20.9 E, 400 m)."""
    return write("stations.csv", STATIONS_CSV)
