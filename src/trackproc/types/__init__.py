"""Plain data types shared above ``methods``: an orbit :class:`State`, a ground :class:`Station`, the
canonical :class:`PassTable`, a reader's :class:`RawMeasurements`, the epoch parser and the value
limits (:mod:`trackproc.types.checks`). This layer sits below ``io`` (pyproject.toml, importlinter):
it imports no reader or writer, so a pipeline or a report can name a type without importing io;
the io modules that read and write each type re-export it under its old name.
"""

from trackproc.types.epoch import parse_epoch  # noqa: F401
from trackproc.types.passes import PassTable  # noqa: F401
from trackproc.types.raw import RawMeasurements  # noqa: F401
from trackproc.types.state import STATE_PARAMETERS, State  # noqa: F401
from trackproc.types.station import Station  # noqa: F401
