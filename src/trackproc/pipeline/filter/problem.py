"""The shared OD core the filter evaluates: the same problem (samples, stations, modifiers and
their bias drivers, force model, priors) and measurement model as ``trackproc estimate``.

The one module of this package that imports the estimate package (re-exports only)."""

from trackproc.pipeline.estimate import EstimateOptions, Problem, build_problem  # noqa: F401
from trackproc.pipeline.estimate.options import UNITS  # noqa: F401

__all__ = ["EstimateOptions", "Problem", "build_problem", "UNITS"]
