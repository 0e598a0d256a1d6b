"""Options, result and constants of ``fit-tle``."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import pandas as pd

from trackproc.methods.estimation.decision import REPLACE_PROBABILITY


KINDS = ("doppler", "range_rate", "range", "azimuth", "elevation")
DOPPLER_BIAS = ("none", "offset", "offset+drift")
APRIORI_MODELS = ("tle", "refine")
#: B* a-priori 1-sigma floor (1/earth radii): B* of LEO objects varies by this much between TLEs.
BSTAR_SIGMA_FLOOR = 1e-4
#: Sampling of the initial orbit when the elements are moved to the new epoch (s), and its half-span (revolutions).
REEPOCH_STEP_S = 60.0
REEPOCH_HALF_SPAN_REV = 1.0
#: Share of edited samples above which the fit is suspect.
EDITED_LIMIT = 0.10
MU_WGS72 = 398600.8e9
#: The fit is written only when it predicts the position at the horizon better than the initial
#: orbit with at least this probability (``no_predictive_gain``; tle_fit.probability_better: 0.5
#: is a coin toss): the rule every command shares (methods/estimation/decision.py).
REFUSAL_PROBABILITY = REPLACE_PROBABILITY


@dataclass
class FitTleOptions:
    """Options of :func:`fit_tle` (defaults = the CLI's)."""

    epoch: Optional[np.datetime64] = None
    fit_bstar: bool = True
    doppler_bias: str = "offset+drift"
    kinds: Optional[list] = None
    earth: str = "wgs84"
    range_rate_model: str = "doppler"
    ephemeris_sigma_m: float = 100.0
    clip: float = 4.0
    max_iterations: int = 30
    satnum: Optional[str] = None
    apriori: bool = True
    cross_validate: bool = False
    #: SGP4's theory error at a pass, in a-priori sigmas; None: tle_theory_error.MODEL_ERROR_SCALE.
    model_error: Optional[float] = None
    #: Keep the initial TLE when the fit cannot be shown to predict better (``refused``).
    refusal: bool = True
    #: The initial orbit's a-priori: "tle" (a TLE's measured accuracy, tle_fit.TLE_APRIORI; the
    #: default for a TLE) or "refine" (refine's default element sigmas; always for a state).
    apriori_model: str = "tle"
    #: The prediction horizon (days after the epoch) at which fit and initial orbit are compared
    #: (``--horizon``).
    prediction_span_days: float = 1.0


@dataclass
class FitTleResult:
    tle: object
    summary: dict
    quality: object
    residuals: pd.DataFrame
    warnings: list = field(default_factory=list)
