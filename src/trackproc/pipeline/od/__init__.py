"""The orbit-determination core shared by the commands that fit an orbit to passes (``estimate``,
``refine``, ``filter``): the options of the problem (:mod:`.options`), the pass tables turned into a
measurement set (:mod:`.samples`), the modifiers the options ask for (:mod:`.modifiers`), the
problem with its parameters and a-priori (:mod:`.problem`: :class:`Problem`, :func:`build_problem`),
its residual tables (:mod:`.residuals`) and the horizon maps of the replace/keep rule
(:mod:`.decision`). The a-priori's policy (its source, conflict test and the decision to replace
or keep the user's orbit) is one layer down, :mod:`trackproc.methods.estimation`.

Command packages import this core, never one another (pyproject.toml's independence contract).
"""

from trackproc.pipeline.od.options import (DOPPLER_BIAS, DOPPLER_BIAS_PER, RESIDUAL_COLUMNS, UNITS,  # noqa: F401
                                           EstimateOptions)
from trackproc.pipeline.od.problem import Problem, build_problem  # noqa: F401
from trackproc.pipeline.od.residuals import residual_frame, rms_table  # noqa: F401

__all__ = ["EstimateOptions", "Problem", "build_problem", "residual_frame", "rms_table", "UNITS", "DOPPLER_BIAS",
           "DOPPLER_BIAS_PER", "RESIDUAL_COLUMNS"]
