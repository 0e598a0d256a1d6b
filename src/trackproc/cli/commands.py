"""Imports every command module so that each registers itself on ``app``.

Add one line per command module. Command modules import only typer and the standard
library at module level.
"""

# isort: off
from trackproc.cli import ingest_cmd  # noqa: F401
from trackproc.cli import info_cmd  # noqa: F401
from trackproc.cli import smooth_cmd  # noqa: F401
from trackproc.cli import simulate_cmd  # noqa: F401
from trackproc.cli import requirements_cmd  # noqa: F401
from trackproc.cli import detect_cmd  # noqa: F401
from trackproc.cli import accuracy_cmd  # noqa: F401
from trackproc.cli import estimate_cmd  # noqa: F401
from trackproc.cli import propagate_cmd  # noqa: F401
from trackproc.cli import batch_cmd  # noqa: F401
