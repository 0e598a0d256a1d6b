"""Imports every command module so that each registers itself on ``app``, and gives each command
its one-line summary for ``trackproc --help``.

Add one line per command module (in the order ``--help`` lists them). Command modules import
only typer and the standard library at module level.
"""

# isort: off
from trackproc.cli import ingest_cmd  # noqa: F401
from trackproc.cli import info_cmd  # noqa: F401
from trackproc.cli import simulate_cmd  # noqa: F401
from trackproc.cli import propagate_cmd  # noqa: F401
from trackproc.cli import smooth_cmd  # noqa: F401
from trackproc.cli import estimate_cmd  # noqa: F401
from trackproc.cli import filter_cmd  # noqa: F401
from trackproc.cli import refine_cmd  # noqa: F401
from trackproc.cli import accuracy_cmd  # noqa: F401
from trackproc.cli import requirements_cmd  # noqa: F401
from trackproc.cli import detect_cmd  # noqa: F401
from trackproc.cli import batch_cmd  # noqa: F401
from trackproc.cli import passes_cmd  # noqa: F401
from trackproc.cli import compare_cmd  # noqa: F401
from trackproc.cli import identify_cmd  # noqa: F401
from trackproc.cli import fit_tle_cmd  # noqa: F401
from trackproc.cli import import_orekit_cmd  # noqa: F401
from trackproc.cli import help_cmd  # noqa: F401
# isort: on

from trackproc.cli.app import app

SUMMARIES = {
    "ingest": "Raw passes (CSV, Parquet, Arrow, CCSDS TDM, DopTrack, .aer) -> validated pass file.",
    "info": "What any file trackproc reads or writes is and holds: kinds, counts, spans, units.",
    "simulate": "Passes of a known orbit with light time, noise, biases: the test bench.",
    "propagate": "Ephemeris, STM, covariance and pass prediction by the DT (Taylor) engine.",
    "smooth": "Least-squares polynomial per pass; TCA and carrier at closest approach (seed 004).",
    "estimate": "Orbit + biases by weighted least squares with error matrices (seed 002).",
    "filter": "Sequential orbit determination: Kalman filter + RTS smoother with process noise, carried night to night.",
    "refine": "Refine a stale orbit from one Doppler pass (seed 004).",
    "accuracy": "Sigma and correlation of a predicted orbit by the differential spectrum (seed 000).",
    "requirements": "Sensor requirement g = sigma*sqrt(dt) for elevation-only detection (seed 003).",
    "detect": "Elevation-only test for an orbit displacement (seed 003).",
    "batch": "Many passes, every night: parallel, resumable, cron-grade.",
    "compare": "Residuals of a pass against a state or TLE: RMS after the pass's own offset and drift.",
    "identify": "Which catalogue TLE is this pass? Ranked fits, likelihood ratios, a verdict.",
    "fit-tle": "Fit a TLE (SGP4 mean elements, B*) to passes or an ephemeris, with covariance and a verdict.",
    "import-orekit": "Orekit orbit-determination configuration (.in) -> stations table, initial state, defaults.",
    "help": "A command's full help (trackproc help CMD), or the manual page (--man).",
    "passes": "Pass schedule of a state or TLE: AOS/TCA/LOS, max elevation, azimuths, Doppler per station.",
}

for _command in app.registered_commands:
    _command.short_help = _command.short_help or SUMMARIES.get(_command.name)
