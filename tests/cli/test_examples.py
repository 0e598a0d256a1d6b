"""Every example in the README and in every command's --help runs, unchanged, on the shipped files
(issue 16): the blocks are extracted, run by bash in a temporary directory where ``sample_data``
is the project's own, and must exit 0 and write the files they name. The ``trackproc`` they call is
a fork of one server that imported trackproc once (tests/cli/forkserver.py: real pipes, files, exit
codes and environment; the interpreter's start is test_startup.py's subject)."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow

#: README blocks that are set-up commands (CI runs them), not examples.
SETUP = ("pip install", "python -m pytest", "python3 -m venv")


def readme_blocks() -> list[str]:
    """The indented code blocks of README.md that run trackproc."""
    blocks, current = [], []
    for line in (ROOT / "README.md").read_text().splitlines() + [""]:
        if line.startswith("    ") and (current or line.strip()):
            current.append(line[4:])
        elif not line.strip() and current:
            current.append("")
        else:
            if current:
                blocks.append("\n".join(current).strip())
            current = []
    if current:
        blocks.append("\n".join(current).strip())
    return [b for b in blocks if re.search(r"(^|\| |\n)trackproc [a-z]", b) and not any(s in b for s in SETUP)
            and not b.startswith("trackproc: error")]


def help_blocks() -> dict[str, str]:
    """Each command's examples, from its help text (``Examples ...:`` up to the next paragraph
    that is not indented)."""
    from typer.main import get_command

    from trackproc.cli.app import _register, app

    _register()
    out = {}
    for name, cmd in get_command(app).commands.items():
        text = cmd.help or ""
        m = re.search(r"Examples?[^\n]*:\n\n(.*?)(?:\n\n(?!    )|\Z)", text, re.S)
        assert m, f"{name} --help has no examples"
        out[name] = "\n".join(line[4:] if line.startswith("    ") else line for line in m.group(1).splitlines())
    return out


def outputs_named(script: str) -> list[str]:
    """Files an example says it writes: -o/--output/--summary/--opm/--residuals/--plot FILE and > FILE."""
    words = shlex.split(script.replace("\\\n", " "), comments=False)
    names = [b for a, b in zip(words, words[1:]) if a in ("-o", "--output", "--summary", "--opm", "--residuals", "--plot", ">")]
    return [n for n in names if n != "-" and not n.startswith("-")]


def _env(bin_dir: Path) -> dict:
    return dict(os.environ, PATH=os.pathsep.join([str(bin_dir), str(Path(sys.executable).parent), os.environ.get("PATH", "")]),
                PYTHONPATH=os.pathsep.join([str(ROOT / "src")] + [p for p in [os.environ.get("PYTHONPATH")] if p]),
                TRACKPROC_LOG_LEVEL="WARNING")


def run(script: str, tmp_path: Path, bin_dir: Path) -> None:
    (tmp_path / "sample_data").symlink_to(ROOT / "sample_data")
    env = _env(bin_dir)
    proc = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, f"example failed (exit {proc.returncode}):\n{script}\n--- stderr:\n{proc.stderr[-3000:]}"
    assert "Traceback" not in proc.stderr
    for name in outputs_named(script):
        path = tmp_path / name
        assert path.exists() and (path.is_dir() or path.stat().st_size > 0), f"{name} not written by:\n{script}"


def test_readme_tour_and_examples_run(tmp_path, forked_trackproc):
    blocks = readme_blocks()
    assert len(blocks) >= 2
    run("\n".join(blocks), tmp_path, forked_trackproc)       # in order: later examples use earlier outputs


@pytest.mark.parametrize("command", ["ingest", "info", "simulate", "propagate", "smooth", "estimate", "filter", "refine",
                                     "accuracy", "requirements", "detect", "batch", "passes", "compare", "identify",
                                     "fit-tle", "import-orekit", "help"])
def test_help_examples_run(command, tmp_path, forked_trackproc):
    run(help_blocks()[command], tmp_path, forked_trackproc)
